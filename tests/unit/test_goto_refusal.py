"""`gcs goto` hears a vehicle's "attitude not flown" whenever it comes: before the mode's
confirming HEARTBEAT (read by the confirmation, not by goto's own loop) or while the stream
starts in a mode the vehicle is already in. A scripted PX4-style vehicle over loopback UDP,
with the real Session."""

from __future__ import annotations

import socket
import threading
import time

import pytest
from pymavlink import mavutil

from common.wire.identity import FLIGHT_CUSTOM_VERSION
from common.wire.mavlink import MAV
from gcs.autopilot import autopilot_of
from gcs.vehicle_link.goto import goto
from gcs.vehicle_link.pose import PoseTarget
from gcs.vehicle_link.session import GcsError, Session

REFUSAL = "attitude not flown: tilt servo 2 would flip"
PX4 = autopilot_of(type("Hb", (), {"autopilot": MAV.MAV_AUTOPILOT_PX4,
                                   "type": MAV.MAV_TYPE_HEXAROTOR})())
OFFBOARD = PX4.resolve_mode("OFFBOARD").custom_mode
HOLD = PX4.resolve_mode("HOLD").custom_mode


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class ScriptedVehicle:
    """This FCU as a ground station sees it (AUTOPILOT_VERSION with its 6-DoF tag, so that
    goto sends attitude targets). Heartbeats, position and attitude at 20 Hz (level, at the
    origin); DO_SET_MODE is
    ACCEPTED and answered with REFUSAL *before* the HEARTBEAT showing the new mode
    (`refuse_on_mode`), or REFUSAL comes with the first attitude target (`refuse_on_stream`,
    a vehicle already in OFFBOARD)."""

    def __init__(self, port: int, *, mode: int, refuse_on_mode: bool,
                 refuse_on_stream: bool) -> None:
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                               source_component=1)
        self.mode, self.refuse_on_mode, self.refuse_on_stream = \
            mode, refuse_on_mode, refuse_on_stream
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _text(self) -> None:
        self.conn.mav.statustext_send(MAV.MAV_SEVERITY_WARNING, REFUSAL.encode())

    def _run(self) -> None:
        mav = self.conn.mav
        next_at = 0.0
        refused = False
        while not self.stop.is_set():
            if time.monotonic() >= next_at:
                next_at = time.monotonic() + 0.05
                mav.heartbeat_send(MAV.MAV_TYPE_HEXAROTOR, MAV.MAV_AUTOPILOT_PX4,
                                   MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED |
                                   MAV.MAV_MODE_FLAG_SAFETY_ARMED, self.mode,
                                   MAV.MAV_STATE_ACTIVE)
                mav.local_position_ned_send(0, 0.0, 0.0, -3.0, 0.0, 0.0, 0.0)
                mav.attitude_quaternion_send(0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            msg = self.conn.recv_match(blocking=True, timeout=0.01)
            if msg is None:
                continue
            kind = msg.get_type()
            if kind == "SET_ATTITUDE_TARGET" and self.refuse_on_stream and not refused:
                refused = True
                self._text()
            elif kind == "COMMAND_LONG":
                if msg.command == MAV.MAV_CMD_DO_SET_MODE:
                    mav.command_ack_send(msg.command, MAV.MAV_RESULT_ACCEPTED)
                    if self.refuse_on_mode:
                        self._text()  # said at once, the new mode's HEARTBEAT after it
                    self.mode = OFFBOARD  # the only mode goto asks for here
                    next_at = time.monotonic() + 0.2
                elif msg.command == MAV.MAV_CMD_REQUEST_MESSAGE and \
                        msg.param1 == MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
                    mav.command_ack_send(msg.command, MAV.MAV_RESULT_ACCEPTED)
                    mav.autopilot_version_send(0, 0, 0, 0, 0, list(FLIGHT_CUSTOM_VERSION),
                                               [0] * 8, [0] * 8, 0, 0, 1)
                else:
                    mav.command_ack_send(msg.command, MAV.MAV_RESULT_ACCEPTED)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=2.0)
        self.conn.close()


@pytest.mark.parametrize("case", ["before_the_confirming_heartbeat", "already_in_offboard"])
def test_goto_ends_with_the_refusal_whenever_it_is_heard(case):
    port = _free_udp_port()
    session = Session(f"udpin:127.0.0.1:{port}")
    vehicle = ScriptedVehicle(port, mode=OFFBOARD if case == "already_in_offboard" else HOLD,
                              refuse_on_mode=case == "before_the_confirming_heartbeat",
                              refuse_on_stream=case == "already_in_offboard")
    try:
        session.wait_vehicle(timeout=5.0)
        target = PoseTarget.from_euler_deg((1.0, -2.0, -3.0), 170.0, 0.0, 60.0)
        t0 = time.monotonic()
        with pytest.raises(GcsError, match="the vehicle does not fly this attitude: "
                                           + REFUSAL):
            goto(session, target, arm_first=False, tolerance_m=0.05, tolerance_rad=0.02,
                 timeout=8.0, hold_s=0.0)
        assert time.monotonic() - t0 < 6.0  # at once, not at the timeout
    finally:
        vehicle.close()
        session.close()


def test_a_refusal_heard_before_the_stream_is_not_ours():
    """A STATUSTEXT from before this goto's targets began (another station's) ends nothing:
    the pose is then reached or timed out on its own."""
    port = _free_udp_port()
    session = Session(f"udpin:127.0.0.1:{port}")
    vehicle = ScriptedVehicle(port, mode=HOLD, refuse_on_mode=False, refuse_on_stream=False)
    try:
        session.wait_vehicle(timeout=5.0)
        vehicle._text()
        deadline = time.monotonic() + 5.0
        while session.text_since(0.0, REFUSAL) is None and time.monotonic() < deadline:
            session.recv(None, timeout=0.05)
        assert session.text_since(0.0, REFUSAL) == REFUSAL
        target = PoseTarget.from_euler_deg((0.0, 0.0, -3.0), 0.0, 0.0, 0.0)
        assert goto(session, target, arm_first=False, tolerance_m=0.05, tolerance_rad=0.02,
                    timeout=5.0, hold_s=0.0) == (0.0, 0.0)
    finally:
        vehicle.close()
        session.close()
