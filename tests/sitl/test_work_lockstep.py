"""In lockstep, work beside the loop changes nothing: a flight with a 500-item upload at a
fixed simulated time (through the mission protocol's messages) and its MISSION_START flies
to the bit the same whether the check and the plan run inline or in the worker process,
and the same again beside two CPU hogs (the loop waits for the worker; simulated time
stands still meanwhile)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_mission_length import mission
from common.config.scenario import load_scenario
from common.logs.columns import ONBOARD_COLUMNS
from common.wire.mav_enums import MAV_RESULT
from common.wire.mavlink import MAV
from common.wire.mission_messages import item_message
from fcu.edge.mission_protocol import MissionServer
from fcu.edge.work_process import ProcessWork
from fcu.pipeline import Pipeline
from fcu.work import InlineWork, Work
from gcs.run.inprocess import run_scenario
from gcs.run.runio import RunResult

ROOT = Path(__file__).resolve().parents[2]
UPLOAD_US, START_US = 4_000_000, 4_500_000  # in the hover before the figure-infinity
DURATION_S = 9.0
M = MAV
pytestmark = pytest.mark.timeout(300)


def _gcs(work: Work) -> tuple[Callable[[int, Pipeline], None], list[int]]:
    """What a ground station does at fixed simulated times: the upload, MISSION_START."""
    answers: list[int] = []
    server: list[MissionServer] = []

    def before_step(t_us: int, pipe: Pipeline) -> None:
        c = pipe.commander
        if not server:
            c.work = work
            server.append(MissionServer(1, 1, c.limits, work=work))
            server[0].on_mission_changed = c.set_mission
        s = server[0]
        if t_us == UPLOAD_US:
            items = mission(500)
            count = M.MAVLink_mission_count_message(1, 1, len(items), 0)
            replies = s.handle(count, 0.0)
            for it in items:
                replies = s.handle(item_message(it, 1, 1), 0.0)
            answers.extend(r.type for r in [*replies, *(m for _, m in s.take_outbox())]
                           if r.get_type() == "MISSION_ACK")
        if t_us == START_US:
            answers.append(c.mission_start(0)[0])

    return before_step, answers


def _fly(work: Work) -> tuple[RunResult, list[int]]:
    scenario = dataclasses.replace(load_scenario(ROOT / "config/scenarios/case1_figure8.toml"),
                                   duration_s=DURATION_S)
    before_step, answers = _gcs(work)
    try:
        return run_scenario(scenario, before_step=before_step), answers
    finally:
        work.close()


def _flown(run: RunResult) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """What the flight was: truth, the onboard rows but the step's wall time, the events."""
    keep = [i for i, name in enumerate(ONBOARD_COLUMNS) if name != "step_us"]
    return run.truth, run.onboard[:, keep], [e.text for e in run.events]


def test_a_500_item_upload_mid_flight_flies_the_same_inline_beside_and_under_load():
    inline, answers = _fly(InlineWork())
    assert answers == [M.MAV_MISSION_ACCEPTED, MAV_RESULT.MAV_RESULT_ACCEPTED]
    assert "mission started" in [e.text for e in inline.events]
    beside, answers_beside = _fly(ProcessWork(wait=True))
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        loaded, answers_loaded = _fly(ProcessWork(wait=True))
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    assert answers_beside == answers_loaded == answers
    ref = _flown(inline)
    for run in (beside, loaded):
        truth, onboard, events = _flown(run)
        assert np.array_equal(truth, ref[0]) and np.array_equal(onboard, ref[1])
        assert events == ref[2]
