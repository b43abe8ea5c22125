"""`gcs.autopilot.commands.flight_state`: the link's latest HEARTBEAT tells the armed state
without waiting only when it came after the latest command sent. An arm's COMMAND_ACK comes
before the HEARTBEAT that shows it armed: `takeoff` right after `arm` read the disarmed
HEARTBEAT from before the arm and said "not armed" (seen against this FCU in real time)."""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any

from common.wire.mavlink import MAV
from gcs.autopilot.commands import flight_state
from gcs.vehicle_link.patience import from_target

M = MAV
ARMED = M.MAV_MODE_FLAG_SAFETY_ARMED | M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
DISARMED = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


def _msg(m: Any, at: float) -> Any:
    m._header = MAV.MAVLink_header(m.get_msgId(), srcSystem=1, srcComponent=1)
    m._timestamp = at
    return m


def _heartbeat(base_mode: int, at: float) -> Any:
    return _msg(M.MAVLink_heartbeat_message(M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_PX4,
                                            base_mode, 0, M.MAV_STATE_ACTIVE, 3), at)


class _Session(SimpleNamespace):
    """What flight_state reads of a Session: the link's latest messages, the latest
    command's time, and the messages that come next."""

    def send(self, msg: Any) -> None:
        pass

    def recv(self, types: list[str], timeout: float) -> Any:
        return self.coming.pop(0) if self.coming else None

    def from_autopilot(self, msg: Any) -> bool:  # as Session's
        return from_target(msg, self.target_system, self.target_component)


def _session(cached_at: float, commanded_at: float) -> _Session:
    now = time.time()
    return _Session(conn=SimpleNamespace(messages={"HEARTBEAT": _heartbeat(DISARMED,
                                                                           cached_at)}),
                    target_system=1, target_component=1, commanded_at=commanded_at,
                    heartbeat_msg=None, coming=[
                        _msg(M.MAVLink_extended_sys_state_message(0, M.MAV_LANDED_STATE_ON_GROUND),
                             now),
                        _msg(M.MAVLink_global_position_int_message(0, 0, 0, 0, 0, 0, 0, 0, 0),
                             now),
                        _heartbeat(ARMED, now)])  # the one that shows the arm


def test_a_heartbeat_from_before_the_latest_command_is_not_the_armed_state():
    now = time.time()
    armed, landed, height = flight_state(_session(now - 0.2, now - 0.1))
    assert armed and landed == M.MAV_LANDED_STATE_ON_GROUND and height == 0.0


def test_a_fresh_heartbeat_after_the_latest_command_is_taken_without_waiting():
    now = time.time()
    armed, _, _ = flight_state(_session(now - 0.1, now - 0.2))
    assert not armed  # the cached one (disarmed), not the ARMED one that came next
