"""Work beside the control loop, through processes (`fcu.work`): in real time the mission
check of a 500-item upload and the mission's plan at MISSION_START run while the loop keeps
stepping, judged in control steps (the FCU's `--stats`: the steps it took while each job was
under way), never in wall time; with `--work inline` they take none (the loop waited), which
is what a regression would show; and every answer is the one the protocol says."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.bench_mission_length import mission
from common.wire.mavlink import MAV
from common.wire.modes import Mode, decode_custom
from gcs.vehicle_link.mission_client import upload

from .conftest import Stack, launch, stop
from .waits import until

M = MAV
ITEMS = 500


def _fly_500(tmp_path: Path, *fcu_args: str) -> tuple[dict, Stack]:
    """Real time, on the ground: upload 500 items, arm, MISSION_START; the FCU's stats."""
    stats = tmp_path / "fcu.json"
    s = launch(tmp_path, "case1_figure8", realtime=True,
               fcu_args=("--stats", str(stats), *fcu_args))
    try:
        sess = s.session
        assert upload(sess.conn, sess.target_system, sess.target_component,
                      mission(ITEMS), send=sess.send) == M.MAV_MISSION_ACCEPTED
        assert sess.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
        assert sess.command(M.MAV_CMD_MISSION_START, 0.0) == M.MAV_RESULT_ACCEPTED
        hb = s.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1
                        and decode_custom(m.custom_mode) == Mode.MISSION)
        assert hb is not None, "no HEARTBEAT in MISSION"
        until(lambda: s.wait_for(["LOCAL_POSITION_NED"], lambda m: m.z < -0.5, 1.0),
              "the take-off to 1 m", 30.0)
    finally:
        s.session.close()
        stop(s.procs)
    return json.loads(stats.read_text()), s


@pytest.mark.timeout(180)
def test_realtime_checks_and_plans_run_while_the_loop_steps(tmp_path):
    """Given the real-time default (`beside`), then the check and the plan each ran while
    the loop took control steps (at least one: inline, it takes none), the upload was
    ACCEPTED, MISSION_START ACCEPTED and the vehicle flew the mission's take-off."""
    stats, _ = _fly_500(tmp_path)
    work = stats["work"]
    assert work["kind"] == "beside" and work["failed"] == 0
    steps = {job["job"]: job["steps"] for job in work["history"]}
    assert set(steps) == {"warm", "check_mission", "plan_from"}, work  # warm: at start
    assert steps["check_mission"] >= 1 and steps["plan_from"] >= 1, work


@pytest.mark.timeout(180)
def test_inline_work_stops_the_loop_for_it(tmp_path):
    """Given `--work inline` in real time (the old way), then the same jobs took no control
    step while they ran: the loop waited for them."""
    stats, _ = _fly_500(tmp_path, "--work", "inline")
    work = stats["work"]
    assert work["kind"] == "inline"
    assert [(j["job"], j["steps"]) for j in work["history"]] == [
        ("check_mission", 0), ("plan_from", 0)]


def _stream_until(s: Stack, target_ned: tuple[float, float, float], mode_set: bool,
                  reached) -> bool:
    """SET_POSITION_TARGET_LOCAL_NED at 20 Hz (wall clock) until `reached(LOCAL_POSITION_NED)`
    or 30 s; OFFBOARD asked once streaming (unless `mode_set`)."""
    import time
    sess = s.session
    deadline = time.monotonic() + 30.0
    asked = mode_set
    start = time.monotonic()
    while time.monotonic() < deadline:
        sess.send(M.MAVLink_set_position_target_local_ned_message(
            0, sess.target_system, sess.target_component, M.MAV_FRAME_LOCAL_NED,
            0b0000_1101_1111_1000, *target_ned, 0, 0, 0, 0, 0, 0, 0.0, 0.0))
        if not asked and time.monotonic() - start > 0.3:
            assert sess.command(M.MAV_CMD_DO_SET_MODE, 1.0, 6.0) == M.MAV_RESULT_ACCEPTED
            asked = True
        msg = s.wait_for(["LOCAL_POSITION_NED"], timeout=0.05)
        if msg is not None and reached(msg):
            return True
    return False


def _job_steps(stats_path: Path, job: str) -> tuple[dict, list[int]]:
    """The FCU's `--stats` work section, and the control steps each `job` took."""
    work = json.loads(stats_path.read_text())["work"]
    return work, [j["steps"] for j in work["history"] if j["job"] == job]


@pytest.mark.timeout(180)
def test_realtime_offboard_samples_are_anchored_beside_the_loop(tmp_path):
    """Given real time (`beside`), OFFBOARD from a hover and set-points 1 m north then 1 m
    east, then the vehicle gets to each, and each new sample's anchor ran while the loop
    took control steps (`advance` jobs in work.history, each with at least one step); HOLD
    asked at speed brakes to rest, its brake planned while the loop stepped."""
    stats_path = tmp_path / "fcu.json"
    s = launch(tmp_path, "case1_figure8", realtime=True, fcu_args=("--stats", str(stats_path)))
    try:
        sess = s.session
        assert sess.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
        assert _stream_until(s, (0.0, 0.0, -1.5), False, lambda m: m.z < -1.4)
        assert _stream_until(s, (1.0, 0.0, -1.5), True, lambda m: m.x > 0.95)
        assert _stream_until(s, (1.0, 1.0, -1.5), True, lambda m: m.y > 0.95)
        # HOLD asked on the way to a set-point 5 m further north, at speed: a brake
        assert _stream_until(s, (6.0, 1.0, -1.5), True, lambda m: m.x > 2.0 and m.vx > 1.0)
        assert sess.command(M.MAV_CMD_DO_SET_MODE, 1.0, *Mode.HOLD.value) == \
            M.MAV_RESULT_ACCEPTED
        until(lambda: s.wait_for(["LOCAL_POSITION_NED"], lambda m: abs(m.vx) < 0.05, 1.0),
              "the vehicle at rest in HOLD", 20.0)
    finally:
        s.session.close()
        stop(s.procs)
    work, anchors = _job_steps(stats_path, "advance")
    assert len(anchors) >= 3 and min(anchors) >= 1 and work["failed"] == 0, work
    brakes = _job_steps(stats_path, "brake_ahead")[1]
    # one brake, or more where one came after its time on a busy machine (planned again);
    # a plan the starved worker had not sent within COAST_MAX_US is made in the loop, the
    # documented reaction (pinned in tests/unit/test_plans_beside.py), and judged there
    assert brakes and min(brakes) >= 1, work
    assert len(brakes) <= 1 + work["late_anchors"] + work["inline_plans"], work


@pytest.mark.timeout(180)
def test_realtime_mission_asked_at_speed_brakes_rests_and_starts_there(tmp_path):
    """Given real time (`beside`), OFFBOARD at speed and mode MISSION asked (its waypoints
    behind the vehicle), then the plan ran while the loop stepped, and the reference (the
    onboard log's, one row a step) braked from its speed with no step in its velocity,
    came to rest, rested there while the plan was made, and the mission leaves from there.
    (The OFFBOARD approach used to fly on while the plan was made, and the reference
    stepped back to where it was asked; then it stopped dead there, its velocity stepping
    to zero.)"""
    from common.logs.ulog import read_topic
    from common.wire.mission_items import MissionItem, local_xy
    nan = float("nan")
    items = [MissionItem(seq, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT, int(seq == 0), 1,
                         0.0, 0.0, 0.0, nan, local_xy(0.0), local_xy(east), -1.5)
             for seq, east in enumerate((1.0, 2.0))]
    stats_path = tmp_path / "fcu.json"
    s = launch(tmp_path, "case1_figure8", realtime=True, fcu_args=("--stats", str(stats_path)))
    try:
        sess = s.session
        assert upload(sess.conn, sess.target_system, sess.target_component, items,
                      send=sess.send) == M.MAV_MISSION_ACCEPTED
        assert sess.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
        assert _stream_until(s, (0.0, 1.0, -1.5), False, lambda m: m.z < -1.4 and m.y > 0.95)
        # a set-point far north: still approached at speed however late (a busy machine)
        # the station's view of the vehicle, and so its MISSION, comes
        assert _stream_until(s, (40.0, 1.0, -1.5), True, lambda m: m.x > 1.0 and m.vx > 0.8)
        assert sess.command(M.MAV_CMD_DO_SET_MODE, 1.0, *Mode.MISSION.value) == \
            M.MAV_RESULT_ACCEPTED
        until(lambda: s.wait_for(["LOCAL_POSITION_NED"], lambda m: m.vx < -0.3, 1.0),
              "the mission flying back south to its first waypoint", 60.0)
    finally:
        s.session.close()
        stop(s.procs)
    work, plans = _job_steps(stats_path, "plan_from")
    assert plans and min(plans) >= 1 and work["failed"] == 0, work
    cols, rows = read_topic(tmp_path / "onboard.ulg", "dq_onboard")
    p = rows[:, [cols.index(c) for c in ("pdx", "pdy", "pdz")]]
    speed = np.linalg.norm(rows[:, [cols.index(c) for c in ("vdx", "vdy", "vdz")]], axis=1)
    fast = int(np.flatnonzero(speed > 0.8)[0])
    at_rest = np.flatnonzero(speed[fast:] < 1e-9)
    assert at_rest.size, "the reference never rested: the mode in force flew on meanwhile"
    rest = fast + int(at_rest[0])  # the first row at rest after the speed
    v = rows[:, [cols.index(c) for c in ("vdx", "vdy", "vdz")]]
    dv = np.linalg.norm(np.diff(v[fast:rest + 1], axis=0), axis=1)
    assert dv.max() < 0.05, (int(dv.argmax()), dv.max())  # braked: no step to rest
    assert speed[fast:rest].max() > 0.8
    moving = rest + int(np.flatnonzero(speed[rest:] >= 1e-9)[0])
    assert np.all(p[rest:moving] == p[rest])  # at rest there until the mission leaves
    assert np.linalg.norm(p[moving] - p[rest]) < 1e-3
