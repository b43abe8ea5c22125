"""The telemetry a command needs, asked for on connect and given back when it leaves.

ArduPilot sends almost nothing on a fresh link until a ground station asks; PX4 and this
project's FCU stream by default. For each message a command needs, the station reads the
link's interval (MAV_CMD_GET_MESSAGE_INTERVAL, answered by MESSAGE_INTERVAL) and, where the
message is off or slower than needed, sets it (MAV_CMD_SET_MESSAGE_INTERVAL); ArduPilot
without that command gets the older REQUEST_DATA_STREAM for the message's stream group. On
leaving, `restore` puts back exactly what was changed, to the interval read before (the
default rate where none was read); the REQUEST_DATA_STREAM groups it started, only for
messages the link did not bring fast enough, are stopped again. Streams this station did
not change are never touched, so another station's are never stopped.

The requests go out together and the answers are read together (a vehicle answers each
GET with an ACK and a MESSAGE_INTERVAL in either order).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeGuard

from common.wire.mavlink import MAV
from gcs.autopilot.dialect import ARDUPILOT, STATION_DIALECT, Autopilot


class SessionLink(Protocol):
    """What the stream requests use of a `gcs.vehicle_link.session.Session` (which calls them)."""

    @property
    def target_system(self) -> int: ...
    @property
    def target_component(self) -> int: ...
    @property
    def autopilot(self) -> Autopilot | None: ...
    def send(self, msg: Any) -> None: ...
    def recv(self, types: list[str] | None = None, timeout: float = 1.0) -> Any: ...
    def addressed_to_me(self, msg: Any) -> bool: ...
    def from_autopilot(self, msg: Any | None) -> TypeGuard[Any]: ...


M = MAV
ANSWER_S = 1.0  # how long to wait for the answers to the GETs and SETs
SLOWER = 1.5  # a stream more than this much slower than asked is sped up
UNKNOWN = None  # an interval that was not read: restored to the default rate

# REQUEST_DATA_STREAM groups as ArduPilot fills them (GCS_MAVLink's stream entries)
ARDUPILOT_GROUPS: dict[str, int] = {
    "SYS_STATUS": M.MAV_DATA_STREAM_EXTENDED_STATUS,
    "GPS_RAW_INT": M.MAV_DATA_STREAM_EXTENDED_STATUS,
    "MISSION_CURRENT": M.MAV_DATA_STREAM_EXTENDED_STATUS,
    "POSITION_TARGET_LOCAL_NED": M.MAV_DATA_STREAM_EXTENDED_STATUS,
    "LOCAL_POSITION_NED": M.MAV_DATA_STREAM_POSITION,
    "GLOBAL_POSITION_INT": M.MAV_DATA_STREAM_POSITION,
    "ATTITUDE": M.MAV_DATA_STREAM_EXTRA1,
    "ATTITUDE_QUATERNION": M.MAV_DATA_STREAM_EXTRA1,
    "EXTENDED_SYS_STATE": M.MAV_DATA_STREAM_EXTRA3,
    "EKF_STATUS_REPORT": M.MAV_DATA_STREAM_EXTRA3,
}

# What each command needs, in Hz
STATUS = {"SYS_STATUS": 2.0, "LOCAL_POSITION_NED": 4.0, "ATTITUDE_QUATERNION": 4.0,
          "ATTITUDE": 4.0, "GLOBAL_POSITION_INT": 4.0, "EXTENDED_SYS_STATE": 2.0}
WATCH = {**STATUS, "POSITION_TARGET_LOCAL_NED": 2.0, "MISSION_CURRENT": 1.0}
GOTO = {"LOCAL_POSITION_NED": 10.0, "ATTITUDE_QUATERNION": 10.0}
TAKEOFF = {"LOCAL_POSITION_NED": 5.0, "GLOBAL_POSITION_INT": 5.0, "EXTENDED_SYS_STATE": 2.0}
READINESS = {"EKF_STATUS_REPORT": 2.0}  # ArduPilot's estimator state (status, watch)


def needs(command: str, kind: str) -> dict[str, float]:
    """The messages (name -> Hz) a CLI command needs from an autopilot of this kind."""
    wanted = {"status": STATUS, "watch": WATCH, "goto": GOTO, "takeoff": TAKEOFF,
              "log": STATUS}.get(command, {})
    if kind == ARDUPILOT and command in ("status", "watch", "log"):
        wanted = {**wanted, **READINESS}
    return dict(wanted)


def _msg_id(name: str) -> int:
    return int(getattr(STATION_DIALECT, f"MAVLINK_MSG_ID_{name}"))


@dataclass
class Streams:
    """What this station changed on the link: message id -> the interval read before (us,
    -1 off; UNKNOWN: not read), and the REQUEST_DATA_STREAM groups it started."""

    changed: dict[int, int | None] = field(default_factory=dict)
    groups: dict[int, float] = field(default_factory=dict)


def _commands(session: SessionLink, command: int, params: list[tuple[float, ...]]
              ) -> tuple[list[int], dict[int, int]]:
    """Send COMMAND_LONGs of one kind together; (their results in order of arrival, the
    MESSAGE_INTERVAL answers heard: id -> interval_us)."""
    s = session
    for p in params:
        full = [*p, *([0.0] * (7 - len(p)))]
        s.send(M.MAVLink_command_long_message(s.target_system, s.target_component, command,
                                              0, *full))
    results: list[int] = []
    intervals: dict[int, int] = {}
    end = time.monotonic() + ANSWER_S
    while (left := end - time.monotonic()) > 0 and (
            len(results) < len(params) or
            (command == M.MAV_CMD_GET_MESSAGE_INTERVAL and len(intervals) < len(params))):
        msg = s.recv(["COMMAND_ACK", "MESSAGE_INTERVAL"], timeout=left)
        if not s.from_autopilot(msg):
            continue
        if msg.get_type() == "MESSAGE_INTERVAL":
            intervals[msg.message_id] = msg.interval_us
        elif msg.command == command and s.addressed_to_me(msg):
            results.append(msg.result)
    return results, intervals


def request(session: SessionLink, wanted: dict[str, float]) -> Streams:
    """Make the link bring `wanted` (name -> Hz); what was changed, for `restore`."""
    streams = Streams()
    if not wanted:
        return streams
    ids = {_msg_id(name): hz for name, hz in wanted.items()}
    results, before = _commands(session, M.MAV_CMD_GET_MESSAGE_INTERVAL,
                                [(float(i),) for i in ids])
    to_set: dict[int, int | None] = {}
    # ArduPilot's 0 is "not available" (the spec's); PX4 answers 0 for any stream it is not
    # sending on this link, which SET_MESSAGE_INTERVAL starts (its MavlinkReceiver's
    # get_message_interval and set_message_interval)
    zero_is_off = session.autopilot is not None and session.autopilot.kind != ARDUPILOT
    for msg_id, hz in ids.items():
        now = before.get(msg_id, UNKNOWN)
        if now == 0 and not zero_is_off:  # "not available": the vehicle has no such stream
            continue
        if now is None or now <= 0 or now > SLOWER * 1e6 / hz:
            to_set[msg_id] = now
    if not to_set:
        return streams
    results, _ = _commands(session, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                           [(float(i), 1e6 / ids[i]) for i in to_set])
    accepted = sum(r == M.MAV_RESULT_ACCEPTED for r in results)
    if accepted == len(to_set):
        streams.changed = to_set
        return streams
    if session.autopilot is not None and session.autopilot.kind == ARDUPILOT and \
            accepted == 0:
        names = {i: n for n, i in ((n, _msg_id(n)) for n in wanted)}
        for msg_id in to_set:
            group = ARDUPILOT_GROUPS.get(names[msg_id])
            if group is not None:
                streams.groups[group] = max(streams.groups.get(group, 0.0), ids[msg_id])
        for group, hz in streams.groups.items():
            session.send(M.MAVLink_request_data_stream_message(
                session.target_system, session.target_component, group, round(hz), 1))
        return streams
    # some were taken: SET's ACKs do not say which, so each taken one is put back on leaving
    streams.changed = to_set
    return streams


def restore(session: SessionLink, streams: Streams) -> None:
    """Put back what `request` changed: each interval as it was read (the default rate
    where it was not read), and stop the stream groups it started."""
    if streams.changed:  # (a 0 read is PX4's stream not sent: stopped again, -1)
        _commands(session, M.MAV_CMD_SET_MESSAGE_INTERVAL,
                  [(float(i), float(-1 if old is not None and old <= 0 else
                                    0 if old is None else old))
                   for i, old in streams.changed.items()])
    for group in streams.groups:
        session.send(M.MAVLink_request_data_stream_message(
            session.target_system, session.target_component, group, 0, 0))
    streams.changed, streams.groups = {}, {}
