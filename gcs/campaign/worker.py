"""One run on a worker: in-process, or through sitl and fcu processes; its row of results."""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
import socket
import tempfile
import time
from pathlib import Path
from typing import Any

from common.config.scenario import load_scenario, scenario_from_data
from common.links import free_port
from gcs.campaign.runs import RunSpec
from gcs.report.run_metrics import RunMetrics


def flatten(metrics: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """metrics.json as flat columns: nested tables joined with '.', events as JSON text."""
    out: dict[str, Any] = {}
    for k, v in metrics.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, name + "."))
        elif isinstance(v, list):
            out[name] = json.dumps(v, separators=(",", ":"))
        else:
            out[name] = v
    return out


def _write_scenario_files(data: dict[str, Any], folder: Path) -> Path:
    """The run's scenario as files the processes read: scenario.toml naming vehicle.toml and
    one gain file per controller, beside it."""
    import tomli_w

    folder.mkdir(parents=True, exist_ok=True)
    data = copy.deepcopy(data)
    (folder / "vehicle.toml").write_text(tomli_w.dumps(data["vehicle"]))
    data["vehicle"] = "vehicle.toml"
    for ctrl, table in list(data["gains"].items()):
        (folder / f"gains_{ctrl}.toml").write_text(tomli_w.dumps(table))
        data["gains"][ctrl] = f"gains_{ctrl}.toml"
    path = folder / "scenario_run.toml"
    path.write_text(tomli_w.dumps(data))
    return path


def warm_worker() -> None:
    """Import what a run needs, once per worker, before the runs are timed."""
    import gcs.run.inprocess
    import gcs.run.process_run  # noqa: F401


START_ATTEMPTS = 3  # a run through processes that could not start is tried again (new ports)


def _through_processes(spec: RunSpec, folder: Path) -> RunMetrics | dict[str, Any]:
    """A run through sitl and fcu processes on their own free ports (or Zenoh prefix), in
    its run folder or a temporary one."""
    from gcs.run.process_run import RunError, one_vehicle, run_processes

    where = folder if spec.keep != "none" else Path(tempfile.mkdtemp(prefix="campaign-run-"))
    metrics: RunMetrics | dict[str, Any] = {}
    try:
        scenario = load_scenario(_write_scenario_files(spec.data, where))
        for attempt in range(1, START_ATTEMPTS + 1):
            # Zenoh: the run's own prefix and its own router on a free port (a router
            # shared by concurrent runs would stop with the run that started it).
            router = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
            try:
                metrics = one_vehicle(run_processes(
                    scenario, where, transport=spec.transport,
                    zenoh_url=f"zenoh:campaign/{spec.run_id}@{router}"))
                break
            except RunError:
                if attempt == START_ATTEMPTS:
                    raise
    finally:
        completed = metrics.get("status") == "completed"
        if spec.keep == "none" or (spec.keep == "failed" and completed):
            shutil.rmtree(where, ignore_errors=True)
    return metrics


def execute_run(spec: RunSpec) -> dict[str, Any]:
    """Fly one run (on a worker) and return its row of results.csv. What happened to the
    vehicle is a status; in-process, a vehicle that refuses the run (its mission, arming)
    is status "refused" with the reason. A run that cannot be carried out raises (through
    processes after START_ATTEMPTS tries): it is not recorded, and a rerun tries again."""
    from gcs.run.inprocess import InProcessError, run_scenario
    from gcs.run.runio import write_run

    t0 = time.monotonic()
    folder = Path(spec.folder)
    row: dict[str, Any] = {"run_id": spec.run_id, "index": spec.index, **spec.params}
    if spec.transport == "in-process":
        scenario = scenario_from_data(copy.deepcopy(spec.data), spec.base)
        try:
            result = run_scenario(scenario, logs=spec.keep != "none")
        except InProcessError as exc:
            row.update(status="refused", status_reason=str(exc))
            return row
        metrics: RunMetrics | dict[str, Any] = result.metrics
        if spec.keep == "all" or (spec.keep == "failed" and metrics["status"] != "completed"):
            src = _write_scenario_files(spec.data, folder)
            write_run(folder, dataclasses.replace(scenario, source=str(src)), result)
    else:
        metrics = _through_processes(spec, folder)
    row.update(flatten({k: v for k, v in metrics.items() if k != "logs"}))
    row["run_wall_s"] = time.monotonic() - t0
    return row

