"""The FCU as a MAVLink autopilot, seen from pymavlink as a ground station."""

from __future__ import annotations

import time

import pytest
from pymavlink import mavutil

from common.wire.mavlink import MAV
from common.wire.modes import Mode

from .waits import until

M = MAV
pytestmark = pytest.mark.timeout(120)


def test_heartbeat_identifies_an_autopilot(stack):
    """HEARTBEAT from component 1, a vehicle type, PX4 as the autopilot (so that pymavlink,
    MAVProxy, QGC and MAVSDK read its custom mode by PX4's names), disarmed, AUTO.LOITER."""
    hb = stack.wait_for(["HEARTBEAT"], lambda m: m.get_srcComponent() == 1)
    assert hb is not None
    assert hb.type == M.MAV_TYPE_HEXAROTOR
    assert hb.autopilot == M.MAV_AUTOPILOT_PX4
    assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.custom_mode == Mode.HOLD.custom_mode
    assert mavutil.mode_string_v10(hb) == "LOITER"
    assert stack.session.target_system == 1


def test_sys_status_bits_are_truthful(stack):
    """SYS_STATUS: the simulated sensors present and healthy (gyro, accelerometer,
    barometer, external pose), no magnetometer, GNSS, RC or fence; pre-arm passes with a
    state; geofence health set (no breach to report); battery not measured."""
    ss = stack.wait_for(["SYS_STATUS"])
    assert ss is not None
    present, health = ss.onboard_control_sensors_present, ss.onboard_control_sensors_health
    for bit in (M.MAV_SYS_STATUS_SENSOR_3D_GYRO, M.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
                M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
                M.MAV_SYS_STATUS_SENSOR_VISION_POSITION, M.MAV_SYS_STATUS_PREARM_CHECK):
        assert present & bit and health & bit
    for bit in (M.MAV_SYS_STATUS_SENSOR_3D_MAG, M.MAV_SYS_STATUS_SENSOR_GPS,
                M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER, M.MAV_SYS_STATUS_GEOFENCE):
        assert not present & bit
    assert health & M.MAV_SYS_STATUS_GEOFENCE
    assert (ss.voltage_battery, ss.current_battery, ss.battery_remaining) == (65535, -1, -1)


def test_autopilot_version_has_the_capabilities_mavsdk_needs(stack):
    """REQUEST_MESSAGE(AUTOPILOT_VERSION) is ACKed and answered with MISSION_INT etc."""
    result = stack.session.command(M.MAV_CMD_REQUEST_MESSAGE,
                                   M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert result == M.MAV_RESULT_ACCEPTED
    msg = stack.wait_for(["AUTOPILOT_VERSION"])
    assert msg is not None
    for cap in (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT, M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET,
                M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
                M.MAV_PROTOCOL_CAPABILITY_MAVLINK2, M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT):
        assert msg.capabilities & cap


def test_every_command_gets_an_ack(stack):
    """Supported commands are ACCEPTED, unknown ones UNSUPPORTED, bad arguments DENIED."""
    s = stack.session
    assert s.command(M.MAV_CMD_NAV_RETURN_TO_LAUNCH) == M.MAV_RESULT_DENIED  # not armed
    assert s.command(M.MAV_CMD_NAV_TAKEOFF) == M.MAV_RESULT_DENIED  # not armed
    assert s.command(M.MAV_CMD_DO_FENCE_ENABLE, 1) == M.MAV_RESULT_UNSUPPORTED
    assert s.command(M.MAV_CMD_DO_SET_SERVO, 1, 1500) == M.MAV_RESULT_UNSUPPORTED
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0.5) == M.MAV_RESULT_DENIED
    assert s.command(M.MAV_CMD_MISSION_START) == M.MAV_RESULT_DENIED  # no mission yet
    assert s.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                     4, 3) == M.MAV_RESULT_ACCEPTED  # AUTO.LOITER = HOLD
    assert s.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                     6) == M.MAV_RESULT_DENIED  # OFFBOARD without a setpoint stream


def _rate(stack, kind: str, seconds: float = 1.5) -> float:
    t0 = time.monotonic()
    n = 0
    while time.monotonic() - t0 < seconds:
        if stack.session.recv([kind], timeout=0.1) is not None:
            n += 1
    return n / seconds


def _interval_us(stack, msg_id: int) -> int:
    s = stack.session
    assert s.command(M.MAV_CMD_GET_MESSAGE_INTERVAL, msg_id) == M.MAV_RESULT_ACCEPTED
    reply = stack.wait_for(["MESSAGE_INTERVAL"], lambda m: m.message_id == msg_id)
    return reply.interval_us


def test_message_interval_changes_the_stream(stack):
    """SET_MESSAGE_INTERVAL: 10 Hz, then off (-1), then back to the default (0); the FCU
    reports the interval in force and the stream follows it."""
    s = stack.session
    msg_id = M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
    assert _interval_us(stack, msg_id) == 20_000  # 50 Hz by default
    default = _rate(stack, "ATTITUDE_QUATERNION")
    assert s.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 100_000) == M.MAV_RESULT_ACCEPTED
    assert _interval_us(stack, msg_id) == 100_000
    slow = _rate(stack, "ATTITUDE_QUATERNION")
    # Rates are wall-clock rates: on a loaded machine 50 Hz may arrive slower, never 10 Hz
    # faster.
    assert 3.0 < slow < 13.0 and default > 1.3 * slow, (default, slow)
    assert s.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, -1) == M.MAV_RESULT_ACCEPTED
    assert _interval_us(stack, msg_id) == -1
    time.sleep(0.2)
    assert _rate(stack, "ATTITUDE_QUATERNION", 1.0) == 0.0
    assert s.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 0) == M.MAV_RESULT_ACCEPTED
    assert _interval_us(stack, msg_id) == 20_000
    assert _rate(stack, "ATTITUDE_QUATERNION") > 1.3 * slow
    assert s.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, 99999, 1000) == M.MAV_RESULT_DENIED


def _param(stack, name: str):
    stack.session.send(M.MAVLink_param_request_read_message(
        stack.session.target_system, stack.session.target_component, name.encode(), -1))
    return stack.wait_for(["PARAM_VALUE"], lambda m: m.param_id == name)


def test_parameters_read_write_and_refuse_unstable_gains(stack):
    """The gains are parameters; a set that breaks k_p k_d > k_i is refused with a reason."""
    s = stack.session
    s.send(M.MAVLink_param_request_list_message(s.target_system, s.target_component))
    seen = {}
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        m = s.recv(["PARAM_VALUE"], timeout=0.2)
        if m is not None:
            seen[m.param_id] = m
            if len(seen) == m.param_count:
                break
    assert len(seen) == next(iter(seen.values())).param_count >= 19
    assert seen["DQ_KPR_X"].param_value == pytest.approx(5.0)
    assert seen["DQ_KIR_X"].param_value == pytest.approx(0.1)
    assert all(len(name) <= 16 for name in seen)

    s.send(M.MAVLink_param_set_message(s.target_system, s.target_component, b"DQ_KPR_X", 6.0,
                                       M.MAV_PARAM_TYPE_REAL32))
    echo = stack.wait_for(["PARAM_VALUE"], lambda m: m.param_id == "DQ_KPR_X")
    assert echo.param_value == pytest.approx(6.0)
    # k_i = 100 > k_p k_d = 60: refused, the old value stays; PARAM_ERROR comes first (MAVSDK
    # reports it), a STATUSTEXT says why
    s.send(M.MAVLink_param_set_message(s.target_system, s.target_component, b"DQ_KIR_X", 100.0,
                                       M.MAV_PARAM_TYPE_REAL32))
    echo = text = error = None
    deadline = time.monotonic() + 5.0
    while (echo is None or text is None) and time.monotonic() < deadline:
        m = s.recv(["PARAM_VALUE", "STATUSTEXT", "PARAM_ERROR"], timeout=0.2)
        if m is not None and m.get_type() == "PARAM_ERROR" and m.param_id == "DQ_KIR_X":
            error = m
        if m is not None and m.get_type() == "PARAM_VALUE" and m.param_id == "DQ_KIR_X":
            echo = m
            assert error is not None  # before the echo
        elif m is not None and m.get_type() == "STATUSTEXT" and "DQ_KIR_X" in m.text:
            text = m
    assert error is not None and error.error == M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE
    assert echo is not None and echo.param_value == pytest.approx(0.1)
    assert text is not None and "k_p k_d > k_i" in text.text
    assert _param(stack, "DQ_KIR_X").param_value == pytest.approx(0.1)
    s.send(M.MAVLink_param_set_message(s.target_system, s.target_component, b"MIS_LAND_SPD",
                                       -1.0, M.MAV_PARAM_TYPE_REAL32))
    echo = stack.wait_for(["PARAM_VALUE"], lambda m: m.param_id == "MIS_LAND_SPD")
    assert echo.param_value == pytest.approx(0.5)


def test_arming_gate_no_rotor_output_when_disarmed(rt_stack):
    """Disarmed on the ground: actuator outputs are zero and the vehicle stays put; armed in
    HOLD the rotors carry the vehicle; disarming in the air is refused unless forced."""
    s = rt_stack.session
    out = rt_stack.wait_for(["ACTUATOR_OUTPUT_STATUS"], timeout=5.0)
    assert out is not None and out.actuator[:6] == [0.0] * 6
    # it stays put for 0.5 s of the vehicle's clock
    pos = rt_stack.wait_for(["LOCAL_POSITION_NED"], lambda m: m.time_boot_ms >=
                            out.time_usec // 1000 + 500, 30.0)
    assert pos is not None and pos.z == pytest.approx(0.0, abs=1e-6)
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    hb = rt_stack.wait_for(["HEARTBEAT"], lambda m: m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb is not None
    out = rt_stack.wait_for(["ACTUATOR_OUTPUT_STATUS"], lambda m: min(m.actuator[:6]) > 500)
    assert out is not None  # hover speeds (~1100 rad/s) to hold the pose
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED  # landed
    out = rt_stack.wait_for(["ACTUATOR_OUTPUT_STATUS"], lambda m: max(m.actuator[:6]) == 0)
    assert out is not None


def test_offboard_stream_loss_falls_back_to_hold(stack):
    """OFFBOARD needs a setpoint stream; when it stops for more than 1 s (COM_OF_LOSS_T, on
    the wall clock: docs/clocks.md), the FCU says so and holds, never sooner. On a loaded
    machine this test's own stream can stall past the timeout: the FCU is then right to
    hold, and the stream is tried again (the FCU's verdict on a stream the test did not
    keep up proves nothing); the loss itself can only come late, never early."""
    s = stack.session

    def setpoint():
        s.send(M.MAVLink_set_position_target_local_ned_message(
            0, s.target_system, s.target_component, M.MAV_FRAME_LOCAL_NED,
            0b0000_1111_1111_1000, 0.5, 0.0, 0.0, 0, 0, 0, 0, 0, 0, 0, 0))

    def lost_said() -> bool:  # everything that has come, read (none dropped unseen)
        said = False
        while (m := s.conn.recv_match(blocking=False)) is not None:
            said |= m.get_type() == "STATUSTEXT" and "offboard" in m.text
        return said

    def mode() -> int:  # the latest HEARTBEAT's (sent on the wall clock, and at a change)
        return s.conn.sysid_state[s.target_system].messages["HEARTBEAT"].custom_mode

    for _ in range(5):
        setpoint()
        time.sleep(0.05)
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    for _attempt in range(5):
        assert s.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                         6) == M.MAV_RESULT_ACCEPTED
        sent, gap, said = time.monotonic(), 0.0, False
        t_end = sent + 1.0
        while time.monotonic() < t_end:
            setpoint()
            now = time.monotonic()
            gap, sent = max(gap, now - sent), now
            time.sleep(0.05)
            said |= lost_said()
        if gap < 0.8 and not said:
            break  # a stream kept up: the FCU never lost it
    else:
        pytest.fail("this test could not keep a setpoint stream up in five tries")
    lost = sent
    until(lost_said, "the offboard loss's STATUSTEXT", timeout=60.0, poll_s=0.02)
    assert time.monotonic() - lost >= 0.9

    def holding() -> bool:
        lost_said()  # reads the HEARTBEATs that have come
        return mode() == Mode.HOLD.custom_mode

    until(holding, "HOLD after the loss", timeout=60.0)


def test_commands_with_bad_parameters_are_denied_with_a_reason(stack):
    """NaN, infinities and out-of-range values: DENIED (never silence) and a STATUSTEXT; a
    mission item out of range is MAV_RESULT_FAILED, as the MAVLink spec says."""
    s = stack.session
    nan, inf = float("nan"), float("inf")
    denied, failed = M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED
    for command, params, result, reason in (
            (M.MAV_CMD_DO_SET_MODE, (nan, 4, 3), denied, "unsupported mode"),
            (M.MAV_CMD_COMPONENT_ARM_DISARM, (inf,), denied, "p1 must be 0 or 1"),
            (M.MAV_CMD_SET_MESSAGE_INTERVAL, (nan, 1000), denied, "no message id"),
            (M.MAV_CMD_DO_SET_MISSION_CURRENT, (1e12,), failed, "no mission item"),
            (M.MAV_CMD_NAV_TAKEOFF, (nan,) * 7, denied, "takeoff: not armed")):
        assert s.command(command, *params) == result
        # the Session keeps the STATUSTEXTs that came with and after the refusal
        assert any(reason in text for text in s.last_texts), (command, s.last_texts)
    assert stack.procs["fcu"].poll() is None
