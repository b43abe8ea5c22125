"""MAVSDK as the ground station of the FCU: the gRPC MAVSDK-Python (`mavsdk` 3.17.4, the
last release of that API under this name) with the `mavsdk_server` binary its wheel ships.

The FCU gets a second GCS link (`--gcs udpout:127.0.0.1:PORT`) on which mavsdk_server
listens (`udpin://127.0.0.1:PORT`); mavsdk_server picks its own free gRPC port (`-p 0`) and
logs it. Lockstep (the default): the simulated flight is the same whatever the machine's
load, and once the scenario's duration is reached the plant's last state stays put, so the
pose MAVSDK reports at the end can be held against the mission's end pose and against the
FCU's own LOCAL_POSITION_NED on the pymavlink link.
"""

from __future__ import annotations

import asyncio
import math
import re
import subprocess
import time
import warnings
from collections.abc import AsyncGenerator
from pathlib import Path

import pytest

from common.config.scenario import load_scenario
from common.links import free_port
from common.wire.mavlink import MAV, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import local_xy

from .conftest import SCENARIOS, launch, stop

with warnings.catch_warnings():
    # mavsdk 3.17.4 announces on import that its name passes to the native binding in 4.0.
    warnings.simplefilter("ignore", FutureWarning)
    import mavsdk
    from mavsdk import System
    from mavsdk.mission_raw import MissionItem

M = MAV
SCENARIO = "case2_impulse"  # airborne in hover at the origin; torque 5-7 s, force 20-22 s
SERVER = Path(mavsdk.__file__).parent / "bin" / "mavsdk_server"

# A hold at the origin, then a pose keyframe: 0.5 m north, 0.25 m west, 0.5 m up, yaw from
# the start's 90 deg (facing east) to 1.75 rad. Every float is exact in float32.
HOLD_S, MOVE_S = 3.0, 4.0
TARGET_NED = (0.5, -0.25, -0.5)
TARGET_YAW = 1.75
PUSHED_FROM_US = 15_000_000  # before the scenario's 5 N push (20-22 s), with a margin
MISSION = [
    MissionItem(0, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_LOITER_TIME, 1, 1, HOLD_S, 0.0, 0.0,
                0.0, 0, 0, 0.0, M.MAV_MISSION_TYPE_MISSION),
    MissionItem(1, M.MAV_FRAME_LOCAL_NED, MAV_CMD_POSE_KEYFRAME, 0, 1, MOVE_S, 0.0, 0.0,
                TARGET_YAW, local_xy(TARGET_NED[0]), local_xy(TARGET_NED[1]), TARGET_NED[2],
                M.MAV_MISSION_TYPE_MISSION),
]
FIELDS = ("seq", "frame", "command", "current", "autocontinue", "param1", "param2", "param3",
          "param4", "x", "y", "z", "mission_type")


class MavsdkServer:
    """The wheel's mavsdk_server on one MAVLink URL, logging to a file; it opens its gRPC
    port (chosen by itself) once it has discovered a system."""

    def __init__(self, url: str, log: Path) -> None:
        self.log = log
        with log.open("wb") as fh:
            self.proc = subprocess.Popen([str(SERVER), "-p", "0", url], stdout=fh,
                                         stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)

    def grpc_port(self, timeout: float) -> int:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = re.search(r"listen on [0-9.]+:(\d+)", self.log.read_text(errors="replace"))
            if found:
                return int(found.group(1))
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(f"mavsdk_server did not serve:\n{self.log.read_text()}")

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


async def _first(stream: AsyncGenerator, predicate, timeout: float):
    """The first item of a MAVSDK stream that satisfies `predicate`; the stream is closed."""
    async def scan():
        async for item in stream:
            if predicate(item):
                return item
        return None
    try:
        return await asyncio.wait_for(scan(), timeout)
    finally:
        await stream.aclose()


async def _first_advancing(stream: AsyncGenerator, predicate, what: str,
                           stall_s: float = 30.0):
    """The first item of a stamped MAVSDK stream (`timestamp_us`: simulated time in
    lockstep) that satisfies `predicate`, waited for while the stamps advance: a loaded
    machine flies slower, never differently. AssertionError naming `what` when no item
    with a later stamp comes for `stall_s` of wall time; the stream is closed."""
    items = stream.__aiter__()
    latest, advanced = -1, time.monotonic()
    try:
        while True:
            left = advanced + stall_s - time.monotonic()
            try:
                item = await asyncio.wait_for(items.__anext__(), max(left, 0.0))
            except TimeoutError:
                raise AssertionError(f"{what}: the stamps stood still at {latest} us for "
                                     f"{stall_s:g} s") from None
            if predicate(item):
                return item
            if item.timestamp_us > latest:
                latest, advanced = item.timestamp_us, time.monotonic()
    finally:
        await stream.aclose()


async def _until(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.02)


async def _record(stream: AsyncGenerator, out: list, clock: list[int]) -> None:
    """Append (simulated time of the latest attitude sample, item) for each item."""
    async for item in stream:
        if hasattr(item, "timestamp_us"):
            clock[0] = item.timestamp_us
        out.append((clock[0], item))


def _distance_to_path(p: tuple[float, float, float]) -> float:
    """Distance from the straight segment origin -> target (the keyframe's path)."""
    t = sum(a * b for a, b in zip(p, TARGET_NED, strict=True)) / sum(c * c for c in TARGET_NED)
    t = min(1.0, max(0.0, t))
    return math.dist(p, tuple(t * c for c in TARGET_NED))


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


async def _fly(grpc_port: int, end_us: int) -> dict:
    drone = System(mavsdk_server_address="127.0.0.1", port=grpc_port)
    await drone.connect()
    state = await _first(drone.core.connection_state(), lambda s: s.is_connected, 20)
    assert state is not None and state.is_connected

    await drone.mission_raw.upload_mission(MISSION)
    back = await drone.mission_raw.download_mission()

    got: dict[str, list] = {"pos": [], "att": [], "progress": [], "mode": []}
    clock = [0]
    tasks = [asyncio.ensure_future(_record(stream, got[key], clock)) for key, stream in (
        ("pos", drone.telemetry.position_velocity_ned()),
        ("att", drone.telemetry.attitude_quaternion()),
        ("progress", drone.mission_raw.mission_progress()),
        ("mode", drone.telemetry.flight_mode()))]
    try:
        # every stream live (it has spoken once) before the flight starts
        await _until(lambda: all(got.values()), 10, f"the first samples of {list(got)}")
        start = got["pos"][-1][1]
        await drone.action.arm()
        await drone.mission_raw.start_mission()
        # The plant stops at the scenario's duration and its last state stays: wait for it
        # while the flight advances.
        end_att = await _first_advancing(drone.telemetry.attitude_quaternion(),
                                         lambda q: q.timestamp_us >= end_us,
                                         "the scenario's end")
        await asyncio.sleep(0.5)  # a few more samples of the final state
        finished = await drone.mission_raw.is_mission_finished()
        armed = await _first(drone.telemetry.armed(), lambda _: True, 5)
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    return {"back": back, "start": start, "end_att": end_att, "finished": finished,
            "armed": armed, **got}


@pytest.mark.timeout(1200)  # a ceiling: the flight is waited for while it advances
def test_mavsdk_uploads_downloads_arms_flies_and_reads_telemetry(tmp_path):
    """Given the FCU with a second GCS link served by mavsdk_server, when MAVSDK connects,
    uploads a LOITER_TIME + pose keyframe mission with mission_raw, downloads it, arms and
    starts it, then the download equals the upload field by field, mission progress advances
    to the end, and MAVSDK's position and attitude are finite, unit-norm, on the mission's
    path, and at the end at the keyframe's pose and equal to the FCU's own telemetry."""
    port = free_port()
    end_us = round(load_scenario(SCENARIOS / f"{SCENARIO}.toml").duration_s * 1e6)
    stack = launch(tmp_path, SCENARIO, fcu_args=("--gcs", f"udpout:127.0.0.1:{port}"))
    server = None
    try:
        server = MavsdkServer(f"udpin://127.0.0.1:{port}", tmp_path / "mavsdk_server.log")
        grpc_port = server.grpc_port(timeout=30)
        r = asyncio.run(asyncio.wait_for(_fly(grpc_port, end_us), 1080))

        def at_end(msg) -> bool:
            return msg.time_boot_ms >= end_us // 1000

        # the FCU's own view of the final state, on the pymavlink link
        fcu_pos = stack.wait_for(["LOCAL_POSITION_NED"], at_end, timeout=10)
        fcu_att = stack.wait_for(["ATTITUDE_QUATERNION"], at_end, timeout=10)
    finally:
        if server is not None:
            server.close()
        stack.session.close()
        stop(stack.procs)

    # mission_raw round trip: every field as uploaded
    assert len(r["back"]) == len(MISSION)
    for up, down in zip(MISSION, r["back"], strict=True):
        for name in FIELDS:
            assert getattr(down, name) == getattr(up, name), (name, up, down)

    # before the flight: lockstep holds the plant at its hover start at the origin
    p0 = r["start"].position
    assert math.dist((p0.north_m, p0.east_m, p0.down_m), (0.0, 0.0, 0.0)) < 1e-3

    # telemetry through the flight: finite, unit quaternions, on the mission's path (the
    # mission ends at 7 s; the scenario's 5 N push at 20-22 s moves the vehicle 0.25 m off
    # the end pose for a few seconds). Samples are timed by the latest attitude's stamp.
    assert len(r["pos"]) > 20 and len(r["att"]) > 20
    for t_us, s in r["pos"]:
        p = (s.position.north_m, s.position.east_m, s.position.down_m)
        v = (s.velocity.north_m_s, s.velocity.east_m_s, s.velocity.down_m_s)
        assert all(math.isfinite(c) for c in (*p, *v))
        assert _distance_to_path(p) < (0.05 if t_us < PUSHED_FROM_US else 0.4), (t_us, p)
    for _, q in r["att"]:
        assert all(math.isfinite(c) for c in (q.w, q.x, q.y, q.z))
        assert abs(math.hypot(q.w, q.x, q.y, q.z) - 1.0) < 1e-4
    assert abs(_yaw(r["att"][0][1]) - math.pi / 2) < 1e-3  # the start faces east

    # the end: the keyframe's pose, held; what MAVSDK reports is what the FCU sends
    end = r["pos"][-1][1].position
    end_q = r["end_att"]
    assert math.dist((end.north_m, end.east_m, end.down_m), TARGET_NED) < 0.05
    assert abs(_yaw(end_q) - TARGET_YAW) < 0.05
    assert fcu_pos is not None and fcu_att is not None
    assert (end.north_m, end.east_m, end.down_m) == pytest.approx(
        (fcu_pos.x, fcu_pos.y, fcu_pos.z), abs=1e-6)
    assert (end_q.w, end_q.x, end_q.y, end_q.z) == pytest.approx(
        (fcu_att.q1, fcu_att.q2, fcu_att.q3, fcu_att.q4), abs=1e-6)

    # progress: current advances item by item to the end of the mission
    currents = [p.current for _, p in r["progress"]]
    assert currents == sorted(currents) and currents[-1] == len(MISSION), currents
    assert len(set(currents)) >= 2, currents
    assert all(p.total == len(MISSION) for _, p in r["progress"])
    assert r["finished"] is True
    # armed, and the mode (PX4 encoding) decoded as HOLD once the mission is done
    assert r["armed"] is True
    done_us = r["progress"][-1][0]
    assert r["mode"][-1][0] > done_us and r["mode"][-1][1].name == "HOLD", r["mode"]


# ------------------------------------------------------------------ MAVSDK as for PX4


class Watch:
    """The test's own view of the FCU (its pymavlink Session), recorded in a thread:
    (wall time, message) for HEARTBEAT, LOCAL_POSITION_NED, EXTENDED_SYS_STATE, STATUSTEXT."""

    KINDS = ("HEARTBEAT", "LOCAL_POSITION_NED", "EXTENDED_SYS_STATE", "STATUSTEXT")

    def __init__(self, session) -> None:
        import threading

        self.session = session
        self.seen: list[tuple[float, object]] = []
        self.running = True
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while self.running:
            msg = self.session.recv(list(self.KINDS), timeout=0.1)
            if msg is not None and msg.get_srcComponent() == 1:
                self.seen.append((time.monotonic(), msg))

    def stop(self) -> None:
        self.running = False
        self.thread.join(timeout=5)

    def of(self, kind: str) -> list:
        return [m for _, m in list(self.seen) if m.get_type() == kind]

    def modes(self) -> list[str]:
        from common.wire.modes import decode_custom

        names: list[str] = []
        for hb in self.of("HEARTBEAT"):
            mode = decode_custom(hb.custom_mode)
            name = mode.name if mode is not None else str(hb.custom_mode)
            if not names or names[-1] != name:
                names.append(name)
        return names


RTL_AWAY_NED = (3.0, -4.0, -2.0)  # where a mission takes the vehicle before RTL


async def _px4_flight(grpc_port: int, watch: Watch) -> dict:
    from mavsdk.action import ActionError
    from mavsdk.param import ParamError
    from mavsdk.telemetry import FlightMode, LandedState

    drone = System(mavsdk_server_address="127.0.0.1", port=grpc_port)
    await drone.connect()
    state = await _first(drone.core.connection_state(), lambda s: s.is_connected, 20)
    assert state is not None and state.is_connected
    r: dict = {}
    # before arming: health as MAVSDK derives it for PX4 (SYS_STATUS, HOME_POSITION,
    # LOCAL_POSITION_NED)
    r["health"] = await _first(drone.telemetry.health(), lambda h: h.is_armable and
                               h.is_local_position_ok and h.is_home_position_ok, 15)
    r["all_ok"] = await _first(drone.telemetry.health_all_ok(), lambda _: True, 5)
    r["battery"] = await _first(drone.telemetry.battery(), lambda _: True, 5)
    r["mode0"] = await _first(drone.telemetry.flight_mode(), lambda _: True, 5)
    # parameters: a refusal is reported as such, not as a timeout
    r["refusals"] = []
    for name, value in (("MIS_LAND_SPD", -1.0), ("DQ_KIR_X", 100.0), ("NO_SUCH_PARAM", 1.0)):
        t0 = time.monotonic()
        try:
            await drone.param.set_param_float(name, value)
        except ParamError as exc:
            r["refusals"].append((name, exc._result.result.name, time.monotonic() - t0))
    r["land_spd"] = await drone.param.get_param_float("MIS_LAND_SPD")
    await drone.action.set_takeoff_altitude(3.0)  # MIS_TAKEOFF_ALT, as for PX4
    await drone.action.set_return_to_launch_altitude(6.0)  # RTL_RETURN_ALT
    r["takeoff_alt"] = await drone.action.get_takeoff_altitude()
    r["rtl_alt"] = await drone.action.get_return_to_launch_altitude()

    await drone.action.arm()
    await drone.action.takeoff()
    r["hold"] = await _first(drone.telemetry.flight_mode(), lambda m: m == FlightMode.HOLD and
                             any(m.text.startswith("takeoff complete")
                                 for m in watch.of("STATUSTEXT")), 60)
    await asyncio.sleep(1.0)
    r["after_takeoff"] = await _first(drone.telemetry.position_velocity_ned(),
                                      lambda _: True, 5)

    # away from home with a one-waypoint mission, then home with RTL
    await drone.mission_raw.upload_mission([MissionItem(
        0, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT, 1, 1, 0.0, 0.0, 0.0, math.nan,
        local_xy(RTL_AWAY_NED[0]), local_xy(RTL_AWAY_NED[1]), RTL_AWAY_NED[2],
        M.MAV_MISSION_TYPE_MISSION)])
    await drone.mission_raw.start_mission()
    await _first(drone.mission_raw.mission_progress(), lambda p: p.current == p.total, 60)
    await _first(drone.telemetry.flight_mode(), lambda m: m == FlightMode.HOLD, 30)
    r["away"] = await _first(drone.telemetry.position_velocity_ned(), lambda _: True, 5)
    await drone.action.return_to_launch()
    r["rtl_mode"] = await _first(drone.telemetry.flight_mode(),
                                 lambda m: m == FlightMode.RETURN_TO_LAUNCH, 10)
    await _first(drone.telemetry.armed(), lambda armed: not armed, 120)
    r["landed"] = await _first(drone.telemetry.landed_state(),
                               lambda s: s == LandedState.ON_GROUND, 10)
    await asyncio.sleep(0.5)
    r["end"] = await _first(drone.telemetry.position_velocity_ned(), lambda _: True, 5)
    try:
        await drone.action.takeoff()  # disarmed: refused, and MAVSDK says so
        r["takeoff_disarmed"] = "SUCCESS"
    except ActionError as exc:
        r["takeoff_disarmed"] = exc._result.result.name
    return r


@pytest.mark.timeout(240)
def test_mavsdk_health_takeoff_and_return_to_launch(tmp_path):
    """Given the FCU (Case I, on the ground, lockstep) seen by MAVSDK as a PX4 autopilot,
    then before arming is_armable, the gyro, accelerometer, local and home position health
    are true (health_all_ok false: no GNSS, no magnetometer), the battery is unknown, refused
    parameter sets are reported as refusals (VALUE_OUT_OF_RANGE, DOES_NOT_EXIST) at once;
    Action.takeoff() climbs MIS_TAKEOFF_ALT (set by MAVSDK) and holds (TAKEOFF then HOLD);
    after a waypoint away, return_to_launch() climbs to RTL_RETURN_ALT, flies home, lands
    and disarms there."""
    port = free_port()
    stack = launch(tmp_path, "case1_figure8", fcu_args=("--gcs", f"udpout:127.0.0.1:{port}"))
    watch = Watch(stack.session)
    server = None
    try:
        server = MavsdkServer(f"udpin://127.0.0.1:{port}", tmp_path / "mavsdk_server.log")
        r = asyncio.run(asyncio.wait_for(_px4_flight(server.grpc_port(timeout=30), watch), 220))
    finally:
        watch.stop()
        if server is not None:
            server.close()
        stack.session.close()
        stop(stack.procs)

    h = r["health"]
    assert h.is_armable and h.is_gyrometer_calibration_ok and h.is_accelerometer_calibration_ok
    assert h.is_local_position_ok and h.is_home_position_ok
    assert not h.is_global_position_ok and not h.is_magnetometer_calibration_ok
    assert r["all_ok"] is False
    b = r["battery"]  # not measured: MAVSDK shows unknown, except SYS_STATUS's voltage
    assert b.remaining_percent == -1.0 and math.isnan(b.current_battery_a)
    assert math.isnan(b.capacity_consumed_ah) and math.isnan(b.temperature_degc)
    assert r["mode0"].name == "HOLD"
    assert [(n, res) for n, res, _ in r["refusals"]] == [
        ("MIS_LAND_SPD", "VALUE_OUT_OF_RANGE"), ("DQ_KIR_X", "VALUE_OUT_OF_RANGE"),
        ("NO_SUCH_PARAM", "DOES_NOT_EXIST")]
    assert all(seconds < 0.5 for *_, seconds in r["refusals"])  # answered, not timed out
    assert r["land_spd"] == pytest.approx(0.5)
    assert r["takeoff_alt"] == pytest.approx(3.0) and r["rtl_alt"] == pytest.approx(6.0)

    p = r["after_takeoff"].position
    assert (p.north_m, p.east_m, p.down_m) == pytest.approx((0.0, 0.0, -3.0), abs=0.03)
    p = r["away"].position
    assert (p.north_m, p.east_m, p.down_m) == pytest.approx(RTL_AWAY_NED, abs=0.05)
    modes = watch.modes()
    assert modes[:4] == ["HOLD", "TAKEOFF", "HOLD", "MISSION"], modes
    assert modes[4:6] == ["HOLD", "RTL"], modes
    downs = [m.z for m in watch.of("LOCAL_POSITION_NED")]
    assert min(downs) == pytest.approx(-6.0, abs=0.05)  # climbed to RTL_RETURN_ALT
    assert r["landed"].name == "ON_GROUND"
    p = r["end"].position
    assert (p.north_m, p.east_m, p.down_m) == pytest.approx((0.0, 0.0, 0.0), abs=0.05)
    texts = [m.text for m in watch.of("STATUSTEXT")]
    assert "landed: disarmed" in texts and "disarmed in the air" not in texts
    assert r["takeoff_disarmed"] == "COMMAND_DENIED"
