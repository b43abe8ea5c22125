"""In-process runs that several tests compare with, flown once per test worker (the tests
that use one share an xdist group, so they run on the same worker)."""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

from common.config.scenario import load_scenario
from gcs.run.inprocess import run_scenario
from gcs.run.runio import RunResult

CASE1 = Path(__file__).resolve().parents[1] / "config" / "scenarios" / "case1_figure8.toml"
GROUP = "case1_reference"  # the xdist group of the tests that use case1_metrics
TOUR_GROUP = "mission_tour"  # the xdist group of the tests that use tour_run


@cache
def case1_metrics() -> dict[str, Any]:
    """metrics.json of Case I (160 s, PID, default actuators) in-process."""
    return run_scenario(load_scenario(CASE1), logs=False).metrics


@cache
def tour_run() -> RunResult:
    """The tour mission (it takes off, flies its legs, lands and disarms) in-process, its
    logs in memory (read-only: shared by the tests that judge it)."""
    return run_scenario(load_scenario(CASE1.parent / "mission_tour.toml"), logs=False)
