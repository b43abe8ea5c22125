"""The per-step work of the in-process run does not grow with the mission: the onboard log
reads only the mission events of the step (the runner consumes them after each step, as
the FCU process's housekeeping does), and still logs every item reached. Timing lives in
benchmarks/bench_mission_length.py."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import gcs.run.inprocess as inprocess
from benchmarks.bench_mission_length import mission
from common.config.scenario import load_scenario
from common.logs.ulog import read_topic
from gcs.mission_files import write_mission

ROOT = Path(__file__).resolve().parents[2]


def test_onboard_log_reads_only_the_new_mission_events(tmp_path, monkeypatch):
    """Given a 60-item mission flown in-process, then at every step the commander holds no
    more than the step's few mission events when the log reads them (not every event since
    the start), and mission_result's seq_reached still climbs to the last item."""
    n = 60
    path = tmp_path / "long.toml"
    write_mission(path, mission(n))
    base = load_scenario(ROOT / "config/scenarios/mission_tour.toml")
    scenario = dataclasses.replace(
        base, duration_s=20.0,
        trajectory=dataclasses.replace(base.trajectory, mission_file=str(path)))
    seen: list[int] = []

    class CountingLog(inprocess.OnboardLog):
        def step(self, out: Any, step_us: float, t_us: int,
                 row: tuple[float, ...] | None = None) -> None:
            seen.append(len(self.pipeline.commander.mission_events))
            super().step(out, step_us, t_us, row)

    monkeypatch.setattr(inprocess, "OnboardLog", CountingLog)
    result = inprocess.run_scenario(scenario)
    assert result.metrics["mission_completed"] is True
    assert sum(seen) >= 2 * n  # every item became current and was reached, once each
    assert max(seen) <= 4  # the step's events only (a short item: reached, next current)
    assert result.onboard_ulog is not None
    log = tmp_path / "onboard.ulg"
    log.write_bytes(result.onboard_ulog)
    columns, rows = read_topic(log, "mission_result")
    reached = rows[:, list(columns).index("seq_reached")]
    assert reached.max() == n - 1 and (reached[1:] >= reached[:-1]).all()
