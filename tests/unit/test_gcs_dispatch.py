"""The FCU's ground-station dispatch as one error boundary (fcu/edge/gcs_server.py).

Property: every message type the server handles, with arbitrary field values (NaN, +-inf,
0, the extremes of each integer type, huge floats), reaches no internal error, and every
answer packs and parses back. Sequences: what one message sets, the next one reads.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from common.config.scenario import load_gains, load_vehicle
from common.links import Link, LinkUrl
from common.wire.mavlink import MAV, encoder, pack, parser
from common.wire.mission_items import PX4_SITL_HOME, MissionItem
from fcu.edge.gcs_server import COMPONENT, HANDLED, GcsServer
from fcu.edge.mission_protocol import MissionServer
from fcu.edge.telemetry import LINK_BUDGET_MSG_S, MAX_INTERVAL_US
from fcu.params import ParamStore, apply_params
from fcu.pipeline import Pipeline
from fcu.stages import VehicleState

M = MAV
ROOT = Path(__file__).resolve().parents[2]
COMMANDS = (M.MAV_CMD_COMPONENT_ARM_DISARM, M.MAV_CMD_DO_SET_MODE, M.MAV_CMD_MISSION_START,
            M.MAV_CMD_DO_SET_MISSION_CURRENT, M.MAV_CMD_NAV_LAND,
            M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_GET_MESSAGE_INTERVAL,
            M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
            M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 65535)


class MemoryLink(Link):
    """A datagram link that keeps what is sent."""

    def __init__(self) -> None:
        self.url = LinkUrl("udpin", "127.0.0.1", 0, text="memory")
        self.sent: list[bytes] = []

    def fileno(self) -> int:
        return -1

    def recv(self) -> list[tuple[object, bytes]]:
        return []

    def send(self, data: bytes) -> None:
        self.sent.append(data)

    def close(self) -> None:
        pass


def make_server(n_links: int = 2) -> tuple[GcsServer, list[MemoryLink]]:
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    gains = load_gains(ROOT / "config/gains/pid_eq30.toml")
    pipeline = Pipeline(vehicle, gains, 500)
    store = ParamStore(gains)
    missions = MissionServer(1, COMPONENT, apply_params(store, pipeline))
    missions.on_mission_changed = lambda items: pipeline.commander.set_mission(tuple(items))
    links = [MemoryLink() for _ in range(n_links)]
    server = GcsServer(list(links), pipeline, store, missions, system_id=1, home=PX4_SITL_HOME,
                       on_params=lambda: setattr(missions, "limits",
                                                 apply_params(store, pipeline)))
    missions.on_set_current = server.set_mission_current
    pipeline.on_state(0, VehicleState((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0),
                                      (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), 0)
    return server, links


def parsed(link: MemoryLink) -> list:
    """Every frame sent on the link, parsed; a frame that does not parse fails the test."""
    p = parser()
    out = []
    for data in link.sent:
        msgs = p.parse_buffer(data) or []
        assert len(msgs) == 1 and msgs[0].get_type() != "BAD_DATA", data
        out.extend(msgs)
    link.sent.clear()
    return out


_INT_RANGES = {"int8_t": (-2**7, 2**7 - 1), "uint8_t": (0, 2**8 - 1),
               "int16_t": (-2**15, 2**15 - 1), "uint16_t": (0, 2**16 - 1),
               "int32_t": (-2**31, 2**31 - 1), "uint32_t": (0, 2**32 - 1),
               "int64_t": (-2**63, 2**63 - 1), "uint64_t": (0, 2**64 - 1)}
_FLOATS = st.one_of(st.sampled_from([0.0, -0.0, math.nan, math.inf, -math.inf, 1e38, -1e38,
                                     3.4e38, 2**31, 2**31 + 5.0, -1.0, 1.0, 0.5, 1e-45]),
                    st.floats(width=32, allow_nan=True, allow_infinity=True))


def _field(ftype: str, length: int, name: str) -> st.SearchStrategy:
    if ftype == "char":
        return st.binary(max_size=length)
    if ftype in ("float", "double"):
        one = _FLOATS
    else:
        lo, hi = _INT_RANGES[ftype]
        one = st.one_of(st.sampled_from([lo, hi, 0, 1, lo + 1, hi - 1]), st.integers(lo, hi))
        if name == "command":
            one = st.one_of(st.sampled_from(COMMANDS), one)
        if name in ("target_system", "target"):
            one = st.sampled_from([0, 1, 2, 255])
    return st.lists(one, min_size=length, max_size=length) if length else one


def message(kind: str) -> st.SearchStrategy:
    cls = getattr(M, f"MAVLink_{kind.lower()}_message")
    # fieldnames and fieldtypes are in declaration order, array_lengths in wire order
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    parts = [_field(t, lengths[name], name) for name, t in zip(cls.fieldnames,
                                                                cls.fieldtypes, strict=True)]
    return st.tuples(*parts).map(lambda values: cls(*values))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(HANDLED).flatmap(message),
                          st.integers(0, 1)), min_size=1, max_size=6))
def test_any_field_values_in_any_sequence(sequence):
    """Given any sequence of handled messages with any field values, on two links, then no
    exception reaches the boundary and every answer packs and parses (also telemetry)."""
    server, links = make_server()
    for msg, index in sequence:
        # Round-trip through the wire: what a peer can send.
        data = pack(encoder(255, 190), msg)
        p = parser()
        for wire_msg in p.parse_buffer(data) or []:
            server.handle(index, wire_msg, now_s=1.0)
        server.tick(2.0)
        server.tick(3.5)
    assert server.internal_errors == 0
    assert server.unsendable == 0
    for link in links:
        parsed(link)


_IDS = st.sampled_from([float(i) for i in (0, 1, 31, 32, 245, 512, 2**24, -1)])
_INTERVALS = st.sampled_from([2.0**31 + 5, 2.0**32, 2.0**31 - 1, 1.0, -1.0, 0.0, -2.0, 1e9,
                              0.4, math.nan])
_SEQUENCE_COMMANDS = (M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_GET_MESSAGE_INTERVAL) * 3 + \
    COMMANDS[:11]
_COMMAND = st.tuples(st.sampled_from(_SEQUENCE_COMMANDS), st.one_of(_IDS, _IDS, _FLOATS),
                     st.one_of(_INTERVALS, _INTERVALS, _FLOATS), _FLOATS, st.integers(0, 1))


@settings(max_examples=400, deadline=None)
@given(st.lists(_COMMAND, min_size=2, max_size=12))
def test_command_sequences_on_two_links(sequence):
    """Given sequences of commands (set then get, request then stream, interval changes on
    one link while the other listens), then nothing reaches the boundary, every answer
    packs, and a link that did not turn its own HEARTBEAT off keeps hearing it."""
    server, links = make_server()
    silenced = [False, False]
    for k, (command, p1, p2, p3, index) in enumerate(sequence):
        _command(server, index, command, p1, p2, p3)
        if command == M.MAV_CMD_SET_MESSAGE_INTERVAL and p1 == 0.0 and p2 == -1.0:
            silenced[index] = True
        elif command == M.MAV_CMD_SET_MESSAGE_INTERVAL and p1 == 0.0 and \
                p2 in (0.0, 1.0, 0.4, 1e9, 2.0**31 - 1):
            silenced[index] = False
        server.tick(10.0 + k)
    for k in range(3):
        server.tick(100.0 + 2 * k)
    assert server.internal_errors == 0 and server.unsendable == 0
    for index, link in enumerate(links):
        kinds = [m.get_type() for m in parsed(link)]
        if not silenced[index]:
            assert "HEARTBEAT" in kinds


def _command(server: GcsServer, index: int, command: int, *params: float) -> None:
    p = [*params, *(0.0,) * (7 - len(params))]
    server.handle(index, M.MAVLink_command_long_message(1, 1, command, 0, *p), now_s=1.0)


def _acks_and_texts(link: MemoryLink) -> tuple[list[int], list[str]]:
    msgs = parsed(link)
    return ([m.result for m in msgs if m.get_type() == "COMMAND_ACK"],
            [m.text for m in msgs if m.get_type() == "STATUSTEXT"])


def test_interval_beyond_int32_is_refused_and_get_answers():
    """Given SET_MESSAGE_INTERVAL above 2^31-1 us then GET (the sequence that ended the
    process), then the set is DENIED with a reason and the get answers the interval in force."""
    server, links = make_server()
    att = M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
    _command(server, 0, M.MAV_CMD_SET_MESSAGE_INTERVAL, att, 2**31 + 100)
    acks, texts = _acks_and_texts(links[0])
    assert acks == [M.MAV_RESULT_DENIED] and any("interval" in t for t in texts)
    _command(server, 0, M.MAV_CMD_GET_MESSAGE_INTERVAL, att)
    msgs = parsed(links[0])
    interval = [m for m in msgs if m.get_type() == "MESSAGE_INTERVAL"]
    assert interval and interval[0].interval_us == 20_000
    _command(server, 0, M.MAV_CMD_SET_MESSAGE_INTERVAL, att, MAX_INTERVAL_US)
    _command(server, 0, M.MAV_CMD_GET_MESSAGE_INTERVAL, att)
    interval = [m for m in parsed(links[0]) if m.get_type() == "MESSAGE_INTERVAL"]
    assert interval[0].interval_us == MAX_INTERVAL_US
    assert server.internal_errors == 0


def test_a_link_silences_only_itself():
    """Given link 0 turning HEARTBEAT off, then link 1 keeps its heartbeat and link 0 its
    other streams."""
    server, links = make_server()
    _command(server, 0, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HEARTBEAT, -1)
    for link in links:
        parsed(link)
    for k in range(1, 6):
        server.tick(10.0 + k)
    kinds = [{m.get_type() for m in parsed(link)} for link in links]
    assert "HEARTBEAT" not in kinds[0] and "SYS_STATUS" in kinds[0]
    assert "HEARTBEAT" in kinds[1]


def test_link_budget_bounds_the_streams():
    """Given every stream asked at 1 us, then each request is clamped to 500 Hz and refused,
    with the reason, once the link's total would pass its budget; the total stays bounded."""
    server, links = make_server()
    schedule = server.links[0].schedule
    before = schedule.rate_msg_s()
    denied = 0
    for msg_id in list(schedule.intervals):
        _command(server, 0, M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1)
        acks, texts = _acks_and_texts(links[0])
        if acks == [M.MAV_RESULT_DENIED]:
            denied += 1
            assert any("budget" in t for t in texts)
    assert denied > 0
    assert schedule.rate_msg_s() <= max(LINK_BUDGET_MSG_S, before)
    assert server.links[1].schedule.rate_msg_s() == pytest.approx(before)  # untouched


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1e30, -2.0, 0.5, 2**31])
def test_range_checked_command_parameters(value):
    """Given absurd parameters to every command, then each is answered (ACK) and nothing
    breaks."""
    server, links = make_server()
    for command in COMMANDS:
        _command(server, 0, command, value, value, value, value, value, value, value)
        acks, _ = _acks_and_texts(links[0])
        assert len(acks) == 1, command
    assert server.internal_errors == 0


def test_land_after_a_far_offboard_target_and_a_rearm():
    """Given an offboard target far away (refused beyond the geofence; a near one flown),
    a divergence disarm and a re-arm, when LAND is commanded by every route, then it is
    accepted and nothing reaches the boundary (the fuzz campaign's ValueError)."""
    server, links = make_server()
    pipe = server.pipeline
    far = M.MAVLink_set_position_target_local_ned_message(0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0,
                                                           1e6, 0.0, 0.0, 0, 0, 0, 0, 0, 0,
                                                           0, 0)
    _command(server, 0, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    server.handle(0, far, now_s=1.0)
    _, texts = _acks_and_texts(links[0])
    assert any("GF_MAX_DIST" in t for t in texts)
    near = far.__class__(0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0, 20.0, 0.0, 0.0, 0, 0, 0, 0, 0,
                         0, 0, 0)
    server.handle(0, near, now_s=1.0)
    _command(server, 0, M.MAV_CMD_DO_SET_MODE, 1, 6, 0)
    assert pipe.commander.mode.name == "OFFBOARD"
    still = VehicleState((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                         (0.0, 0.0, 0.0))
    for t_us in range(2000, 10_000_000, 2000):  # the vehicle does not follow: it diverges
        pipe.on_state(t_us, still, t_us)
        pipe.step(t_us)
        if not pipe.armed:
            break
    assert not pipe.armed and t_us > 1_000_000  # the reference moved off at bounded speed
    _command(server, 0, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    hold = pipe.commander.modes.brake.hold
    assert hold is not None and hold.p_enu_m == (0.0, 0.0, 0.0)
    parsed(links[0])
    for route in ((M.MAV_CMD_NAV_LAND,), (M.MAV_CMD_DO_SET_MODE, 1, 4, 6)):
        _command(server, 0, *route)
        acks, _ = _acks_and_texts(links[0])
        assert acks == [M.MAV_RESULT_ACCEPTED]
    assert server.internal_errors == 0 and pipe.commander.modes.descent.plan is not None


def test_a_forged_frame_does_not_lock_a_signed_stream_out():
    """Given a signed link, when a frame signed with another key and a timestamp far ahead
    arrives on a sender's stream, then it is refused and the sender's next validly signed
    frames are still accepted; a replay is refused."""
    from common.wire.mavlink import signed_parser

    key, stolen = bytes(range(32)), bytes(32)
    stamps: dict = {}
    fcu_parser = signed_parser(key, stamps)

    def frame(signing_key: bytes, timestamp: int) -> bytes:
        mav = encoder(255, 190)
        mav.signing.secret_key = signing_key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = 0
        mav.signing.timestamp = timestamp
        return pack(mav, M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))

    def accepted(data: bytes) -> bool:
        msgs = fcu_parser.parse_buffer(data) or []
        return any(m.get_type() == "HEARTBEAT" for m in msgs)

    from common.wire.mavlink import signing_timestamp

    now = signing_timestamp()
    first = frame(key, now)
    assert accepted(first)
    assert not accepted(first)  # replay
    assert not accepted(frame(stolen, now + 10**12))  # forged, far ahead
    assert accepted(frame(key, now + 10))  # the real sender goes on
    assert not accepted(frame(key, now - 6000 * 1000 * 2 - 10**9)[:-1])  # truncated, old


def test_mission_replies_go_to_the_uploading_link_and_notes_are_bounded():
    """Given an upload from link 0 and a second uploader on link 1 refused as busy, then the
    re-requests of the first upload go to link 0 only; and refusal notes replayed for
    duplicate items stay within the link's STATUSTEXT budget."""
    server, links = make_server()

    def sent_by(sysid: int, msg):
        return parser().parse_buffer(pack(encoder(sysid, 190), msg))[0]

    server.handle(0, sent_by(255, M.MAVLink_mission_count_message(1, 1, 3, 0)), now_s=1.0)
    server.handle(1, sent_by(254, M.MAVLink_mission_count_message(1, 1, 2, 0)), now_s=1.0)
    answer = [m for m in parsed(links[1]) if m.get_type() == "MISSION_ACK"]
    assert answer and answer[0].type == M.MAV_MISSION_DENIED  # busy with link 0's upload
    parsed(links[0])
    server.tick(1.5)
    assert not [m for m in parsed(links[1]) if m.get_type() == "MISSION_REQUEST_INT"]
    assert any(m.get_type() == "MISSION_REQUEST_INT" for m in parsed(links[0]))
    # A refused upload (a keyframe the rotors cannot fly), then its last item 200 times.
    server2, links2 = make_server()
    fast = M.MAVLink_mission_item_int_message(1, 1, 0, M.MAV_FRAME_LOCAL_NED, 31000, 0, 1,
                                              0.2, 0.0, 0.0, 0.0, 50000, 0, -3.0, 0)
    server2.handle(0, M.MAVLink_mission_count_message(1, 1, 1, 0), now_s=2.0)
    for k in range(201):
        server2.handle(0, fast, now_s=2.0 + k * 0.001)
    msgs = parsed(links2[0])
    acks = [m.type for m in msgs if m.get_type() == "MISSION_ACK"]
    texts = [m for m in msgs if m.get_type() == "STATUSTEXT"]
    assert acks and set(acks) == {M.MAV_MISSION_DENIED}
    assert 1 <= len(texts) <= 20 + 10 * 0.2 + 1 and server2.texts_dropped > 0  # burst + rate


def test_parsers_are_bounded_whatever_the_peers():
    """Given datagrams from 5,000 peers (source ports cycling), then at most MAX_PARSERS
    parsers are kept."""
    from fcu.edge.gcs_server import MAX_PARSERS

    server, _ = make_server()
    hb = pack(encoder(255, 190), M.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
    for port in range(5000):
        server.on_datagram(0, ("127.0.0.1", 20000 + port), hb, now_s=1.0)
    assert len(server.parsers) <= MAX_PARSERS and server.internal_errors == 0


def test_a_refusal_answers_only_the_link_that_asked():
    """Given two links, when link 0's request is refused, then the ACK and the reason go to
    link 0 only: link 1 hears nothing of it."""
    server, links = make_server()
    parsed(links[0]), parsed(links[1])
    _command(server, 0, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
             2**31 + 100)
    acks, texts = _acks_and_texts(links[0])
    assert acks == [M.MAV_RESULT_DENIED] and texts
    assert _acks_and_texts(links[1]) == ([], [])


def _sent(link: MemoryLink, kind: str) -> list:
    return [m for m in parsed(link) if m.get_type() == kind]


def test_refused_param_set_answers_param_error_first():
    """Given PARAM_SETs refused (out of range; unknown name), then the link that asked gets
    PARAM_ERROR (VALUE_OUT_OF_RANGE with the index; DOES_NOT_EXIST with -1) before the
    unchanged PARAM_VALUE, and the other link hears nothing; an accepted set is echoed to
    every link."""
    server, links = make_server()
    for link in links:
        parsed(link)
    sent = M.MAVLink_param_set_message(1, 1, b"MIS_LAND_SPD", -1.0, M.MAV_PARAM_TYPE_REAL32)
    server.handle(0, parser().parse_buffer(pack(encoder(245, 190), sent))[0], now_s=1.0)
    msgs = [m for m in parsed(links[0]) if m.get_type() in ("PARAM_ERROR", "PARAM_VALUE")]
    assert [m.get_type() for m in msgs] == ["PARAM_ERROR", "PARAM_VALUE"]
    err, value = msgs
    assert err.error == M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE and err.param_id == "MIS_LAND_SPD"
    assert (err.target_system, err.target_component) == (245, 190)
    assert err.param_index == server.params.index("MIS_LAND_SPD") and value.param_value == 0.5
    assert parsed(links[1]) == []
    server.handle(0, M.MAVLink_param_set_message(1, 1, b"NO_SUCH", 1.0, 9), now_s=1.0)
    err = _sent(links[0], "PARAM_ERROR")
    assert err[0].error == M.MAV_PARAM_ERROR_DOES_NOT_EXIST and err[0].param_index == -1
    server.handle(0, M.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 4.0, 9), now_s=1.0)
    assert [m.param_value for m in _sent(links[1], "PARAM_VALUE")] == [4.0]
    assert server.pipeline.commander.flight.takeoff_alt_m == 4.0


def test_a_read_of_a_parameter_that_does_not_exist_answers_param_error():
    """Given PARAM_REQUEST_READs of an unknown name and of an index past the table, then the
    link that asked gets PARAM_ERROR DOES_NOT_EXIST with the id and index as asked (the
    parameter protocol's get error) and nothing else; the other link hears nothing; a
    known name is answered with its PARAM_VALUE."""
    server, links = make_server()
    for link in links:
        parsed(link)
    read = encoder(245, 190)
    for request in (M.MAVLink_param_request_read_message(1, 1, b"NO_SUCH", -1),
                    M.MAVLink_param_request_read_message(1, 1, b"", 5000)):
        server.handle(0, parser().parse_buffer(pack(read, request))[0], now_s=1.0)
    msgs = [m for m in parsed(links[0]) if m.get_type().startswith("PARAM_")]
    assert [(m.get_type(), m.param_id, m.param_index, m.error) for m in msgs] == [
        ("PARAM_ERROR", "NO_SUCH", -1, M.MAV_PARAM_ERROR_DOES_NOT_EXIST),
        ("PARAM_ERROR", "", 5000, M.MAV_PARAM_ERROR_DOES_NOT_EXIST)]
    assert all((e.target_system, e.target_component) == (245, 190) for e in msgs)
    assert parsed(links[1]) == []
    server.handle(0, M.MAVLink_param_request_read_message(1, 1, b"MIS_LAND_SPD", -1), now_s=1.0)
    assert [m.param_id for m in _sent(links[0], "PARAM_VALUE")] == ["MIS_LAND_SPD"]


def test_heartbeat_and_sys_status_tell_the_truth():
    """HEARTBEAT: MAV_AUTOPILOT_PX4, PX4's custom mode and base flags (MANUAL_INPUT in
    POSCTL). SYS_STATUS: present = the simulated IMU, barometer, external pose, AHRS,
    controllers, outputs, pre-arm check; no magnetometer, GNSS, RC (until MANUAL_CONTROL),
    fence; geofence health set (no breach), pre-arm healthy with a state; battery not
    measured."""
    server, _ = make_server()
    hb = server.build(M.MAVLINK_MSG_ID_HEARTBEAT)[0]
    assert hb.autopilot == M.MAV_AUTOPILOT_PX4 and hb.custom_mode == 4 << 16 | 3 << 24
    assert hb.base_mode & M.MAV_MODE_FLAG_AUTO_ENABLED
    ss = server.build(M.MAVLINK_MSG_ID_SYS_STATUS)[0]
    present, health = ss.onboard_control_sensors_present, ss.onboard_control_sensors_health
    for bit in (M.MAV_SYS_STATUS_SENSOR_3D_GYRO, M.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
                M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
                M.MAV_SYS_STATUS_SENSOR_VISION_POSITION, M.MAV_SYS_STATUS_AHRS,
                M.MAV_SYS_STATUS_PREARM_CHECK, M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS):
        assert present & bit and health & bit and ss.onboard_control_sensors_enabled & bit
    for bit in (M.MAV_SYS_STATUS_SENSOR_3D_MAG, M.MAV_SYS_STATUS_SENSOR_GPS,
                M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER, M.MAV_SYS_STATUS_GEOFENCE,
                M.MAV_SYS_STATUS_SENSOR_OPTICAL_FLOW):
        assert not present & bit
    assert health & M.MAV_SYS_STATUS_GEOFENCE and not health & M.MAV_SYS_STATUS_SENSOR_GPS
    assert (ss.voltage_battery, ss.current_battery, ss.battery_remaining) == (65535, -1, -1)
    server.handle(0, M.MAVLink_manual_control_message(1, 0, 0, 500, 0, 0), now_s=5.0)
    server.now_s = 5.1
    ss = server.build(M.MAVLINK_MSG_ID_SYS_STATUS)[0]
    rc = M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    assert ss.onboard_control_sensors_present & rc and ss.onboard_control_sensors_health & rc
    _command(server, 0, M.MAV_CMD_DO_SET_MODE, 1 | 64 | 16, 3, 0)
    assert server.pipeline.commander.mode.name == "POSCTL"
    hb = server.build(M.MAVLINK_MSG_ID_HEARTBEAT)[0]
    assert hb.base_mode & M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED and hb.custom_mode == 3 << 16
    server.now_s = 6.0
    ss = server.build(M.MAVLINK_MSG_ID_SYS_STATUS)[0]
    assert ss.onboard_control_sensors_present & rc and not ss.onboard_control_sensors_health & rc
    server.pipeline.state = None
    ss = server.build(M.MAVLINK_MSG_ID_SYS_STATUS)[0]
    assert not ss.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK


def test_manual_control_for_another_system_is_ignored():
    server, _ = make_server()
    c = server.pipeline.commander
    server.handle(0, M.MAVLink_manual_control_message(2, 1000, 0, 500, 0, 0), now_s=1.0)
    assert c.modes.posctl.sticks == (0.0, 0.0, 0.0, 0.0) and server.ignored_messages == 1
    server.handle(0, M.MAVLink_manual_control_message(1, 1000, 0, 500, 0, 0), now_s=1.0)
    assert c.modes.posctl.sticks.forward == 1.0


def test_commands_and_setpoints_for_another_component_are_not_the_vehicles():
    """An ARM and an OFFBOARD position target addressed to another component of this system
    (a camera, 100; a companion computer, 191) are ignored, as PX4's receiver ignores
    them: not armed, no ACK, no set-point; to the autopilot (1) or to all (0) they act."""
    server, links = make_server()
    c = server.pipeline.commander
    server.handle(0, M.MAVLink_command_long_message(1, 100, M.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                    1, 0, 0, 0, 0, 0, 0), now_s=1.0)
    server.handle(0, M.MAVLink_set_position_target_local_ned_message(
        0, 1, 191, M.MAV_FRAME_LOCAL_NED, 0b1111_1111_1000, 1.0, 2.0, -3.0, 0, 0, 0, 0, 0, 0,
        0, 0), now_s=1.0)
    assert not c.armed and c.offboard.p_enu_m is None and server.ignored_messages == 2
    assert _acks_and_texts(links[0])[0] == []
    server.handle(0, M.MAVLink_command_long_message(1, 0, M.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                    1, 0, 0, 0, 0, 0, 0), now_s=1.0)
    assert c.armed and _acks_and_texts(links[0])[0] == [M.MAV_RESULT_ACCEPTED]


def test_set_mission_current_out_of_range_fails_and_minus_one_is_the_current_item():
    """DO_SET_MISSION_CURRENT as common.xml says: a seq out of range is MAV_RESULT_FAILED;
    p1 -1 is the current item (accepted, nothing changes)."""
    server, links = make_server()
    c = server.pipeline.commander
    _command(server, 0, M.MAV_CMD_DO_SET_MISSION_CURRENT, 99)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_FAILED]
    c.set_mission(tuple(MissionItem(i, M.MAV_FRAME_LOCAL_NED, M.MAV_CMD_NAV_WAYPOINT,
                                    int(i == 0), 1, 0.0, 0.0, 0.0, math.nan, 10_000 * i, 0,
                                    -2.0) for i in range(3)))
    _command(server, 0, M.MAV_CMD_DO_SET_MISSION_CURRENT, 1)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_ACCEPTED] and c.mission_current == 1
    _command(server, 0, M.MAV_CMD_DO_SET_MISSION_CURRENT, -1)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_ACCEPTED] and c.mission_current == 1
    _command(server, 0, M.MAV_CMD_DO_SET_MISSION_CURRENT, 3)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_FAILED] and c.mission_current == 1


def test_takeoff_and_rtl_commands():
    """NAV_TAKEOFF: refused disarmed; armed with p7 NaN -> TAKEOFF; NAV_RETURN_TO_LAUNCH and
    DO_SET_MODE AUTO.RTL -> RTL; each ACKed once."""
    server, links = make_server()
    nan = math.nan
    _command(server, 0, M.MAV_CMD_NAV_TAKEOFF, nan, nan, nan, nan, nan, nan, nan)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_DENIED]
    _command(server, 0, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    _command(server, 0, M.MAV_CMD_NAV_TAKEOFF, nan, nan, nan, nan, nan, nan, nan)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_ACCEPTED]
    assert server.pipeline.commander.mode.name == "TAKEOFF"
    _command(server, 0, M.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_ACCEPTED]
    assert server.pipeline.commander.mode.name == "RTL"
    _command(server, 0, M.MAV_CMD_DO_SET_MODE, 1, 4, 3)
    _command(server, 0, M.MAV_CMD_DO_SET_MODE, 1, 4, 5)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_ACCEPTED] * 2
    assert server.pipeline.commander.mode.name == "RTL"
    assert server.internal_errors == 0


def test_a_mode_change_is_announced_at_once():
    """Given the HEARTBEAT streams due in a second, when the mode changes, then the next tick
    sends a HEARTBEAT with the new mode on every link that has the stream on (once), and
    none on a link that turned it off."""
    server, links = make_server()
    server.tick(100.0)
    _command(server, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HEARTBEAT, -1)
    server.tick(100.1)
    for link in links:
        parsed(link)
    _command(server, 0, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    server.tick(100.2)
    server.tick(100.3)
    beats = [m for m in parsed(links[0]) if m.get_type() == "HEARTBEAT"]
    assert len(beats) == 1 and beats[0].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
    assert not [m for m in parsed(links[1]) if m.get_type() == "HEARTBEAT"]
    server.tick(101.0)  # the cadence goes on from the announcement
    assert not [m for m in parsed(links[0]) if m.get_type() == "HEARTBEAT"]
    server.tick(101.25)
    assert [m for m in parsed(links[0]) if m.get_type() == "HEARTBEAT"]


def _taken_in(server, t_us: int) -> int:
    """Control steps of 2 ms after `t_us` until no mission start is under way (a start asked
    while the reference moves waits for HOLD's brake); the last step's time."""
    while server.pipeline.commander.modes.mission_run.plan is not None:
        t_us += 2000
        server.pipeline.step(t_us)
        assert t_us < 10_000_000, "the start was never taken in"
    return t_us


def test_a_retried_command_is_answered_not_executed_again():
    """Given MISSION_START executed and the flight under way, when the sender re-sends it
    with confirmation 1 (its ACK was lost or late, as on a loaded machine), then the vehicle
    answers ACCEPTED again and the mission keeps its start time; a fresh MISSION_START
    (confirmation 0) and a retry that differs in a parameter are executed."""
    from common.config.scenario import load_scenario
    from gcs.run.scenario_mission import scenario_mission

    server, links = make_server()
    c = server.pipeline.commander
    c.set_mission(tuple(scenario_mission(load_scenario(
        ROOT / "config/scenarios/case1_figure8.toml"))))

    def start(confirmation: int, first: float = 0.0, now_s: float = 1.0) -> None:
        server.handle(0, M.MAVLink_command_long_message(
            1, 1, M.MAV_CMD_MISSION_START, confirmation, first, 0, 0, 0, 0, 0, 0), now_s)

    def started_at() -> float:
        assert c.modes.mission_run.executor is not None
        return c.modes.mission_run.executor._t_start

    _command(server, 0, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    start(0)
    for k in range(1, 11):
        server.pipeline.step(k * 2000)
    t0 = started_at()
    start(1, now_s=1.5)
    start(2, now_s=2.0)
    assert _acks_and_texts(links[0])[0] == [M.MAV_RESULT_ACCEPTED] * 4
    assert started_at() == t0 and server.repeated_commands == 2
    server.pipeline.step(22_000)
    start(1, now_s=1.0 + 6.0)  # beyond the retry window: a new command
    t_us = _taken_in(server, 22_000)  # (the reference moves: braked first)
    assert started_at() > t0
    first = c.modes.mission_run.executor
    server.pipeline.step(t_us + 2000)
    start(0, now_s=7.1)  # confirmation 0: a new command, whatever came before
    t_us = _taken_in(server, t_us + 2000)
    second = c.modes.mission_run.executor
    assert second is not first  # planned again: executed
    server.pipeline.step(t_us + 2000)
    start(1, first=1.0, now_s=7.2)  # another item: not a retry of the last one
    _taken_in(server, t_us + 2000)
    assert c.modes.mission_run.executor is not second and c.mission_current == 1
    # a retry of a refused command repeats the refusal and its reason
    start(0, first=999.0, now_s=8.0)
    start(1, first=999.0, now_s=8.1)
    acks, texts = _acks_and_texts(links[0])
    assert acks[-2:] == [M.MAV_RESULT_DENIED] * 2
    assert sum("999" in t for t in texts) == 2
    assert server.internal_errors == 0
