"""The run metrics record (gcs/report/run_metrics.py): what build_metrics writes is the
record, metrics.json read back is checked, and a file that is not a run's metrics is refused
with what is wrong."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.outcome import LIMIT, Event
from gcs.report.metrics import add_link_timing, build_metrics
from gcs.report.run_metrics import (
    REQUIRED,
    FleetMetrics,
    MetricsError,
    RunMetrics,
    metrics_from_json,
)
from gcs.run.process_run import fleet_of, one_vehicle

ROOT = Path(__file__).resolve().parents[2]
KEYS = set(RunMetrics.__annotations__)


def _hover_metrics(compile_time_s: float | None = None) -> RunMetrics:
    scenario = dataclasses.replace(load_scenario(ROOT / "config/scenarios/case2_sine.toml"),
                                   duration_s=1.0)
    t = np.arange(0.0, 1.0 + 1e-9, 0.002)
    truth = np.zeros((len(t), len(TRUTH_COLUMNS)))
    onboard = np.zeros((len(t), len(ONBOARD_COLUMNS)))
    for log, columns in ((truth, TRUTH_COLUMNS), (onboard, ONBOARD_COLUMNS)):
        log[:, columns.index("time_us")] = np.round(t * 1e6)
    truth[:, TRUTH_COLUMNS.index("qw")] = 1.0
    onboard[:, ONBOARD_COLUMNS.index("qw")] = onboard[:, ONBOARD_COLUMNS.index("qdw")] = 1.0
    return build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard,
                         events=[Event(500_000, 4, "a warning", LIMIT)], wall_time_s=0.5,
                         transport="in-process", lockstep=True,
                         compile_time_s=compile_time_s)


def test_build_metrics_writes_the_record_and_reads_back_equal():
    """Given a run's metrics, then every required key is there, no key is outside the record,
    and the JSON file read back is accepted and equal (events in Event.as_json's form)."""
    m = _hover_metrics(compile_time_s=0.25)
    assert REQUIRED <= m.keys() <= KEYS and m["compile_time_s"] == 0.25
    assert m["events"] == [Event(500_000, 4, "a warning", LIMIT).as_json()]
    back = metrics_from_json(json.loads(json.dumps(m)))
    assert back == m
    add_link_timing(back, {"sim_rtt": {"median_us": 50.0}}, {"stage_us": {"step": 3.0}},
                    "udp", lockstep=True)
    assert back["step_wall_us"] == pytest.approx(0.5 / back["samples"] * 1e6)
    assert back["udp_rtt_us"] == back["link_rtt_us"] == 50.0
    assert back["step_stages_us"] == {"sitl": {"step": 3.0}} and back.keys() <= KEYS


@pytest.mark.parametrize(("edit", "said"), [
    (lambda m: m.pop("status"), "missing status"),
    (lambda m: m.pop("position_error_m"), "missing position_error_m"),
    (lambda m: m.update(samples=True), "samples is bool"),
    (lambda m: m.update(sim_time_s="12"), "sim_time_s is str"),
    (lambda m: m.update(events={}), "events is dict"),
])
def test_a_file_that_is_not_a_runs_metrics_is_refused_with_why(edit, said):
    m = json.loads(json.dumps(_hover_metrics()))
    edit(m)
    with pytest.raises(MetricsError, match=said):
        metrics_from_json(m)
    with pytest.raises(MetricsError, match="not a JSON object"):
        metrics_from_json([m])


def test_one_vehicle_and_a_fleet_are_told_apart():
    m = _hover_metrics()
    fleet: FleetMetrics = {"fleet": 2, "spacing_m": 3.0, "transport": "udp",
                           "scenario": "s", "all_completed": True, "vehicles": {"1": m}}
    assert one_vehicle(m) is m and fleet_of(fleet) is fleet
    with pytest.raises(ValueError):
        one_vehicle(fleet)
    with pytest.raises(ValueError):
        fleet_of(m)
