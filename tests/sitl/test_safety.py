"""Failsafes, signed links and SIGKILL of a process, with real `sitl` and `fcu` processes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from pymavlink import mavutil

from common.config.scenario import load_scenario
from common.links import free_port
from common.wire.mavlink import MAV, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import MissionItem, local_xy
from gcs.run.scenario_mission import scenario_mission
from gcs.vehicle_link.mission_client import download, upload

from .conftest import ROOT, SCENARIOS, launch, stop
from .test_run_folder import _flown_s
from .waits import flown_to, until

M = MAV
pytestmark = pytest.mark.timeout(180)


def _set(stack, name: str, value: float) -> None:
    s = stack.session
    s.send(M.MAVLink_param_set_message(s.target_system, s.target_component, name.encode(),
                                       value, M.MAV_PARAM_TYPE_REAL32))
    echo = stack.wait_for(["PARAM_VALUE"], lambda m: m.param_id == name)
    assert echo is not None and echo.param_value == pytest.approx(value)


def _texts(stack, pattern: str, timeout: float):
    """The first STATUSTEXT containing `pattern` within `timeout`, or None."""
    return stack.wait_for(["STATUSTEXT"], lambda m: pattern in m.text, timeout)


def _fly_keyframe(stack, east_m: float, seconds: float) -> None:
    """A mission with one aggressive pose keyframe, armed and started."""
    s = stack.session
    item = MissionItem(0, M.MAV_FRAME_LOCAL_NED, MAV_CMD_POSE_KEYFRAME, 1, 1, seconds, 0.0,
                       0.0, 0.0, 0, local_xy(east_m), 0.0)
    assert upload(s.conn, s.target_system, s.target_component, [item], send=s.send) == 0
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert s.command(M.MAV_CMD_MISSION_START) == M.MAV_RESULT_ACCEPTED


def _mode(stack, mode_name: str, timeout: float = 5.0):
    from common.wire.modes import Mode

    want = Mode[mode_name].custom_mode
    return stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                          m.custom_mode == want, timeout)


@pytest.fixture
def endless_stack(tmp_path):
    """`stack` whose simulation does not end at the scenario's 60 s: the GCS link's timers
    run on the FCU's wall clock, and a lockstep flight on an idle machine flies 60 s of
    simulated time in the 2.5 s they take, after which no control step logs the LAND."""
    s = launch(tmp_path, sitl_args=("--end-time", "3600"))
    yield s
    s.session.close()
    stop(s.procs)


def test_gcs_link_loss_holds_then_lands(endless_stack):
    """No GCS heartbeat for COM_DL_LOSS_T: HOLD (CRITICAL, announced); after COM_DL_LAND_T
    in HOLD: LAND; heartbeats back: announced."""
    stack = endless_stack
    _set(stack, "COM_DL_LOSS_T", 1.0)
    _set(stack, "COM_DL_LAND_T", 1.5)
    s = stack.session
    mission = scenario_mission(load_scenario(SCENARIOS / "case2_impulse.toml"))
    assert upload(s.conn, s.target_system, s.target_component, mission, send=s.send) == 0
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert s.command(M.MAV_CMD_MISSION_START) == M.MAV_RESULT_ACCEPTED
    s._stop.set()  # the session's heartbeat thread stops: the link is "lost"
    s._thread.join()
    text = _texts(stack, "GCS link lost: HOLD", 5.0)
    assert text is not None and text.severity == M.MAV_SEVERITY_CRITICAL
    hb = _mode(stack, "HOLD")
    assert hb is not None and hb.system_status == M.MAV_STATE_CRITICAL
    text = _texts(stack, "GCS link lost: LAND", 5.0)
    assert text is not None and _mode(stack, "LAND") is not None
    s.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
    text = _texts(stack, "GCS link regained", 3.0)
    assert text is not None
    _onboard_log_tells_the_same_story(stack.logs / "onboard.ulg", len(mission))


def _onboard_log_tells_the_same_story(path, mission_items: int) -> None:
    """The FCU's onboard.ulg, read while it runs: the parameters set over MAVLink, armed in
    MISSION, then HOLD and LAND with the GCS link lost, as PX4's topics say them."""
    from common.logs import px4_topics as px4
    from common.logs.ulog import open_ulog

    # The mode changes on the FCU's wall clock (link check) and is logged with the next
    # control step, which in lockstep waits for the simulator: on a loaded machine the
    # HEARTBEAT can show LAND before the log does. Wait for the log's state, not a time.
    deadline = time.monotonic() + 20.0
    while True:
        u = open_ulog(path)
        status = u.get_dataset("vehicle_status").data
        nav = list(status["nav_state"])
        if nav[-1] == px4.NAVIGATION_STATE_AUTO_LAND or time.monotonic() > deadline:
            break
        time.sleep(0.1)
    changed = {name: value for _, name, value in u.changed_parameters}
    assert changed == {"COM_DL_LOSS_T": 1.0, "COM_DL_LAND_T": 1.5}
    arming = list(status["arming_state"])
    assert px4.ARMING_STATE_ARMED in arming
    lost = np.flatnonzero(status["gcs_connection_lost"])
    assert len(lost) and all(status["failsafe"][lost])
    seen = [n for i, n in enumerate(nav) if i == 0 or n != nav[i - 1]]
    assert seen[-3:] == [px4.NAVIGATION_STATE_AUTO_MISSION, px4.NAVIGATION_STATE_AUTO_LOITER,
                         px4.NAVIGATION_STATE_AUTO_LAND]
    assert nav[lost[0]] == px4.NAVIGATION_STATE_AUTO_LOITER
    flags = u.get_dataset("failsafe_flags").data
    assert flags["gcs_connection_lost"].any() and not flags["local_position_invalid"].any()
    assert not flags["auto_mission_missing"][-1]
    result = u.get_dataset("mission_result").data
    assert result["seq_total"][-1] == mission_items and result["valid"][-1]
    texts = [m.message for m in u.logged_messages]
    assert "failsafe: GCS link lost: HOLD" in texts and "failsafe: GCS link lost: LAND" in texts


def _kill_simulator_in_flight(stack, expect: str, within_s: float):
    """Fly a gentle keyframe, SIGKILL the SITL after 1 s, and wait for the FCU to say
    `expect`; the STATUSTEXT, which must come within `within_s` of the kill."""
    _fly_keyframe(stack, 0.5, 5.0)
    flown_to(stack, 1.0)
    stack.procs["sitl"].send_signal(signal.SIGKILL)
    killed = time.monotonic()
    text = _texts(stack, expect, 5.0)
    assert text is not None and time.monotonic() - killed < within_s
    return text


def test_lockstep_simulator_killed_is_reported_not_a_failsafe(stack):
    """SIGKILL of the SITL mid-flight in lockstep: simulated time stands still with it, so
    the FCU says "simulator not responding" (wall clock, within SIM_SILENT_S plus a margin)
    and does not disarm: a stopped world is no reason to drop the vehicle (docs/clocks.md)."""
    _kill_simulator_in_flight(stack, "simulator not responding", 3.0)
    assert _texts(stack, "state input lost", 1.5) is None
    hb = stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1)
    assert hb is not None and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED


def test_realtime_state_loss_disarms(rt_stack):
    """Real time: SIGKILL of the SITL mid-flight is state-input loss on the FCU's clock: it
    reports it within COM_STATE_LOSS_T (1 s) plus a margin and stops commanding motion."""
    _kill_simulator_in_flight(rt_stack, "state input lost", 2.5)
    hb = rt_stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and not
                           m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb is not None and hb.system_status == M.MAV_STATE_CRITICAL
    status = rt_stack.wait_for(["SYS_STATUS"])
    assert status.onboard_control_sensors_health != status.onboard_control_sensors_present


def test_saturation_aborts_the_mission_to_hold(stack):
    """A keyframe 30 m away in 1 s saturates the rotors; with COM_SAT_ACT = 1 the mission is
    aborted to HOLD with a message (divergence limit raised so it does not act first)."""
    _set(stack, "MIS_ENV_CHK", 0.0)  # accept a profile the rotors cannot fly
    _set(stack, "COM_SAT_T", 0.2)
    _set(stack, "COM_SAT_ACT", 1.0)
    _set(stack, "COM_DIV_POS", 1000.0)
    _fly_keyframe(stack, 30.0, 1.0)
    text = _texts(stack, "rotors saturated", 10.0)
    assert text is not None and "HOLD" in text.text
    assert _mode(stack, "HOLD") is not None


def test_divergence_disarms_and_reports(stack):
    """Tracking error beyond COM_DIV_POS: disarm, EMERGENCY, and a message naming it."""
    _set(stack, "MIS_ENV_CHK", 0.0)  # accept a profile the rotors cannot fly
    _set(stack, "COM_DIV_POS", 0.5)
    _fly_keyframe(stack, 40.0, 1.0)
    text = _texts(stack, "diverged", 10.0)
    assert text is not None and text.severity == M.MAV_SEVERITY_EMERGENCY
    hb = stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                        m.system_status == M.MAV_STATE_EMERGENCY)
    assert hb is not None and not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED


def test_signed_link_flies_and_refuses_unsigned_wrong_and_replayed(tmp_path):
    """With a signing key: the signed session uploads, arms and flies; unsigned and wrongly
    signed ARM and MISSION_COUNT are ignored; a replayed signed frame is rejected; telemetry
    is signed; the refusals are counted."""
    key = tmp_path / "key"
    assert subprocess.run([sys.executable, "-m", "gcs.cli", "keygen", str(key)], cwd=ROOT,
                          check=False).returncode == 0
    gcs_port = free_port()
    stack = launch(tmp_path, fcu_args=("--signing-key", str(key), "--gcs",
                                       f"udpin:127.0.0.1:{gcs_port}"))
    # The fixture's own session listens unsigned on the first GCS link: it hears the signed
    # telemetry but cannot command.
    from common.wire.mavlink import read_signing_key

    secret = read_signing_key(str(key))
    try:
        hb = stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1)
        assert hb is not None and hb.get_msgbuf()[2] & 1  # MAVLINK_IFLAG_SIGNED: signed

        def fresh(signing_key):
            conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{gcs_port}",
                                              source_system=200, source_component=190)
            if signing_key is not None:
                conn.setup_signing(signing_key, sign_outgoing=True)
            return conn

        arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0,
                                             0, 0, 0, 0)
        count = M.MAVLink_mission_count_message(1, 1, 1, 0)
        for bad in (fresh(None), fresh(bytes(32))):
            for msg in (arm, count):
                bad.mav.send(msg)
            time.sleep(0.5)  # deliberate: the window in which no answer may come
            assert not any(m.get_type() == "MISSION_REQUEST_INT" for m in _drain(bad))
            bad.close()
        assert stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                              m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 1.5) is None

        good = fresh(secret)
        raw = []
        good.mav.file = _Tap(good.mav.file, raw)
        good.mav.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, 8, 0, 0, 0, 3))
        mission = scenario_mission(load_scenario(SCENARIOS / "case2_impulse.toml"))
        assert upload(good, 1, 1, mission) == M.MAV_MISSION_ACCEPTED
        assert len(download(good, 1, 1)) == 1
        good.mav.send(arm)
        arm_frame = raw[-1]
        assert arm_frame[2] & 1  # signed (MAVLINK_IFLAG_SIGNED)
        assert stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                              m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 5.0) is not None
        # replay the signed ARM frame after disarming: refused (timestamp not newer)
        disarm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0,
                                                21196, 0, 0, 0, 0, 0)
        good.mav.send(disarm)
        assert stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and not
                              m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 5.0) is not None
        good.write(arm_frame)
        assert stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1 and
                              m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 2.0) is None
        good.close()
        status = stack.wait_for(["SYS_STATUS"], lambda m: m.errors_count1 >= 5, 5.0)
        assert status is not None  # 4 unsigned/wrong + 1 replay, counted
    finally:
        stack.session.close()
        stop(stack.procs)


class _Tap:
    """Keeps a copy of every frame a pymavlink MAVLink object writes."""

    def __init__(self, inner, frames: list) -> None:
        self.inner, self.frames = inner, frames

    def write(self, buf: bytes) -> None:
        self.frames.append(bytes(buf))
        self.inner.write(buf)


def _drain(conn, seconds: float = 0.3) -> list:
    out = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        m = conn.recv_match(blocking=True, timeout=0.05)
        if m is not None:
            out.append(m)
    return out


def test_sigkill_of_the_ground_station_leaves_a_readable_tlog(tmp_path):
    """SIGKILL of `gcs run` mid-run: mavlogdump reads its tlog to the last complete frame,
    and the children, told by the kernel that their parent died, stop by themselves."""
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "run",
                             str(SCENARIOS / "case1_figure8.toml"), "--out", str(out)],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    tlog = out / "flight.tlog"
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (not tlog.exists() or
                                               tlog.stat().st_size < 50_000):
            time.sleep(0.2)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        gone = False
        deadline = time.monotonic() + 15
        while not gone and time.monotonic() < deadline:
            try:
                os.killpg(proc.pid, 0)  # any of our children still alive?
                time.sleep(0.2)
            except ProcessLookupError:
                gone = True
        assert gone, "children outlived the killed ground station"
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # our own process group only
        except ProcessLookupError:
            pass
    dump = subprocess.run([sys.executable, str(_mavlogdump()), str(tlog)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert dump.returncode == 0, dump.stderr
    log = mavutil.mavlink_connection(str(tlog))
    count = 0
    while log.recv_match() is not None:
        count += 1
    assert count > 500 and len(dump.stdout.splitlines()) == count


def _mavlogdump():
    from pathlib import Path

    return Path(sys.executable).parent / "mavlogdump.py"


def test_gcs_run_reports_a_dead_child_and_leaves_none_behind(tmp_path):
    """When the FCU dies mid-run, `gcs run` says which child died and why, and stops the
    other one."""
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "gcs.cli", "run",
                             str(SCENARIOS / "case1_figure8.toml"), "--out", str(out)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        fcu_pid = None
        while fcu_pid is None and time.monotonic() < deadline:
            time.sleep(0.2)
            listing = subprocess.run(["ps", "-o", "pid=,args=", "-g", str(proc.pid)],
                                     capture_output=True, text=True, check=False).stdout
            fcu_pid = next((int(line.split()[0]) for line in listing.splitlines()
                            if "fcu.edge.node" in line), None)
        assert fcu_pid is not None
        until(lambda: _flown_s(out / "flight.tlog") >= 1.0, "the flight's start", 90.0)
        os.kill(fcu_pid, signal.SIGKILL)  # a child of our own ground station
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 1
        assert "fcu exited with status -9" in err

        def left() -> str:
            return subprocess.run(["ps", "-o", "pid=,args=", "-g", str(proc.pid)],
                                  capture_output=True, text=True, check=False).stdout

        until(lambda: "sitl.node" not in left(), f"sitl stopped (left: {left()})", 10.0)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
