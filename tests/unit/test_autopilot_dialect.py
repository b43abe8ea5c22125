"""The ground station's autopilot dialects (gcs.autopilot): mode tables and encodings per
autopilot, mode confirmation, takeoff, goto set-points, telemetry requests, health and
readiness, against scripted vehicles."""

from __future__ import annotations

import collections
import math
from types import SimpleNamespace

import pytest
from pymavlink import mavutil

from common.wire import modes as px4_modes
from common.wire.identity import FLIGHT_CUSTOM_VERSION, flies_pose
from common.wire.mavlink import encoder, parser
from fcu.edge.telemetry import autopilot_version
from gcs.autopilot import PORTABLE_NAMES, UnknownMode, autopilot_of, commands, health, streams
from gcs.autopilot.dialect import STATION_DIALECT as A
from gcs.vehicle_link.actions import set_mode
from gcs.vehicle_link.patience import from_target
from gcs.vehicle_link.pose import PoseTarget, pose_errors
from gcs.vehicle_link.session import GcsError
from gcs.vehicle_link.snapshot import Snapshot
from gcs.vehicle_link.status import heartbeat_mode, mode_name

M = A  # the station's dialect: common and ArduPilot's messages
ARDUCOPTER = autopilot_of(SimpleNamespace(autopilot=M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                          type=M.MAV_TYPE_HEXAROTOR))
PX4 = autopilot_of(SimpleNamespace(autopilot=M.MAV_AUTOPILOT_PX4, type=M.MAV_TYPE_HEXAROTOR))


def _ap(mav_type: int, autopilot: int = M.MAV_AUTOPILOT_ARDUPILOTMEGA):
    return autopilot_of(SimpleNamespace(autopilot=autopilot, type=mav_type))


# ------------------------------------------------------------------ identity and modes


def test_identity_from_the_heartbeat():
    assert (ARDUCOPTER.kind, ARDUCOPTER.vehicle, ARDUCOPTER.mission_home_at_seq0,
            ARDUCOPTER.firmware_type) == ("ardupilot", "copter", True, 3)
    assert (PX4.kind, PX4.mission_home_at_seq0, PX4.firmware_type) == ("px4", False, 12)
    generic = _ap(M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_GENERIC)  # read as PX4, as MAVSDK does
    assert generic.kind == "px4" and generic.resolve_mode("HOLD") == PX4.resolve_mode("HOLD")
    assert [_ap(t).vehicle for t in (M.MAV_TYPE_QUADROTOR, M.MAV_TYPE_FIXED_WING,
                                     M.MAV_TYPE_GROUND_ROVER, M.MAV_TYPE_SUBMARINE)] == \
        ["copter", "plane", "rover", "sub"]


def test_every_arducopter_mode_round_trips():
    for number, name in mavutil.mode_mapping_acm.items():
        target = ARDUCOPTER.resolve_mode(name.lower())
        assert (target.name, target.custom_mode, target.takeoff) == (name, number, False)
        assert ARDUCOPTER.mode_name(number) == name
        assert ARDUCOPTER.set_mode_params(number) == (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                                      number, 0.0)
    assert ARDUCOPTER.mode_name(99) == "Mode(99)"


def test_every_mode_of_plane_rover_sub_round_trips():
    for mav_type, table in ((M.MAV_TYPE_FIXED_WING, mavutil.mode_mapping_apm),
                            (M.MAV_TYPE_GROUND_ROVER, mavutil.mode_mapping_rover),
                            (M.MAV_TYPE_SUBMARINE, mavutil.mode_mapping_sub)):
        ap = _ap(mav_type)
        for number, name in table.items():
            assert ap.resolve_mode(name).custom_mode == number
            assert ap.mode_name(number) == name


PORTABLE = {  # portable name -> the mode each autopilot engages (None: it has none)
    "copter": {"HOLD": "BRAKE", "LOITER": "LOITER", "MISSION": "AUTO", "LAND": "LAND",
               "RTL": "RTL", "POSCTL": "POSHOLD", "OFFBOARD": "GUIDED"},
    "plane": {"HOLD": "LOITER", "LOITER": "LOITER", "MISSION": "AUTO", "TAKEOFF": "TAKEOFF",
              "LAND": "AUTOLAND", "RTL": "RTL", "POSCTL": "CRUISE", "OFFBOARD": "GUIDED"},
    "rover": {"HOLD": "HOLD", "LOITER": "LOITER", "MISSION": "AUTO", "TAKEOFF": None,
              "LAND": None, "RTL": "RTL", "POSCTL": "STEERING", "OFFBOARD": "GUIDED"},
    "sub": {"HOLD": "POSHOLD", "LOITER": "POSHOLD", "MISSION": "AUTO", "TAKEOFF": None,
            "LAND": "SURFACE", "RTL": "SURFACE", "POSCTL": "POSHOLD", "OFFBOARD": "GUIDED"},
}
TYPES = {"copter": M.MAV_TYPE_HEXAROTOR, "plane": M.MAV_TYPE_FIXED_WING,
         "rover": M.MAV_TYPE_GROUND_ROVER, "sub": M.MAV_TYPE_SUBMARINE}


@pytest.mark.parametrize("vehicle", sorted(PORTABLE))
def test_portable_names_per_ardupilot_vehicle(vehicle):
    ap = _ap(TYPES[vehicle])
    table = {v: k for k, v in mavutil.mode_mapping_bynumber(TYPES[vehicle]).items()}
    for name, own in PORTABLE[vehicle].items():
        if own is None:
            with pytest.raises(UnknownMode, match=f"unknown mode {name} on Ardu"):
                ap.resolve_mode(name)
            continue
        target = ap.resolve_mode(name)
        assert (target.name, target.custom_mode) == (own, table[own]), name
    assert set(PORTABLE[vehicle]) | {"TAKEOFF"} >= set(PORTABLE_NAMES)


def test_takeoff_is_a_procedure_on_copter_and_px4():
    copter = ARDUCOPTER.resolve_mode("takeoff")
    assert copter.takeoff and copter.custom_mode == 4  # flown in GUIDED
    px4 = PX4.resolve_mode("TAKEOFF")
    assert px4.takeoff and px4.custom_mode == px4_modes.Mode.TAKEOFF.custom_mode


def test_px4_encodings_unchanged():
    """PX4's names (and this FCU's) encode as before: p2 main mode, p3 sub mode."""
    for name in px4_modes.names():
        mode = px4_modes.by_name(name)
        assert mode is not None
        if mode is px4_modes.Mode.TAKEOFF:
            continue  # the takeoff procedure
        target = PX4.resolve_mode(name)
        assert target.custom_mode == mode.custom_mode
        assert PX4.set_mode_params(target.custom_mode) == (
            M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, *map(float, mode.value))
        assert PX4.mode_name(mode.custom_mode) == mode.name
    assert PX4.resolve_mode("return").name == "RTL"
    for name, (_base, main, sub) in mavutil.px4_map.items():  # PX4's other own modes
        target = PX4.resolve_mode(name)
        assert PX4.set_mode_params(target.custom_mode)[1:] == (main, sub)


def test_the_px4_encoding_is_not_sent_to_ardupilot():
    """The bug: PX4's LAND (AUTO 4 / LAND 6) read by ArduCopter as 4 = GUIDED."""
    assert ARDUCOPTER.set_mode_params(ARDUCOPTER.resolve_mode("LAND").custom_mode)[1:] == \
        (9.0, 0.0)
    assert ARDUCOPTER.set_mode_params(ARDUCOPTER.resolve_mode("OFFBOARD").custom_mode)[1:] == \
        (4.0, 0.0)


def test_unknown_names_list_the_autopilots_names():
    with pytest.raises(UnknownMode) as err:
        ARDUCOPTER.resolve_mode("ALTCTL")
    text = str(err.value)
    assert text.startswith("unknown mode ALTCTL on ArduCopter (one of STABILIZE, ACRO")
    assert all(n in text for n in ("BRAKE", "POSHOLD", "HOLD", "MISSION", "OFFBOARD"))
    with pytest.raises(UnknownMode, match="unknown mode BRAKE on PX4 \\(one of HOLD, "):
        PX4.resolve_mode("BRAKE")


def test_same_mode_px4_sub_mode_counts_only_under_auto():
    hold, mission = (PX4.resolve_mode(n).custom_mode for n in ("HOLD", "MISSION"))
    assert PX4.same_mode(hold, hold) and not PX4.same_mode(hold, mission)
    posctl = PX4.resolve_mode("POSCTL").custom_mode
    assert PX4.same_mode(posctl, posctl | (3 << 24))
    assert not ARDUCOPTER.same_mode(4, 5)


# ------------------------------------------------------------------ a scripted vehicle


def _decoded(msg, system: int = 1, component: int = 1):
    """`msg` as it arrives from (system, component)."""
    data = msg.pack(encoder(system, component))
    return parser().parse_buffer(data)[0]


def _heartbeat(custom_mode: int, armed: bool = False, component: int = 1,
               autopilot: int = M.MAV_AUTOPILOT_ARDUPILOTMEGA):
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return _decoded(M.MAVLink_heartbeat_message(M.MAV_TYPE_HEXAROTOR, autopilot, base,
                                                custom_mode, M.MAV_STATE_STANDBY, 3),
                    component=component)


class Vehicle:
    """A scripted vehicle behind a Session-like object: `on_command(msg)` gives the replies
    to each COMMAND_LONG; `after_ack` messages follow each ACK."""

    def __init__(self, autopilot=ARDUCOPTER, on_command=None) -> None:
        self.autopilot = autopilot
        self.target_system = self.target_component = 1
        self.heartbeat_msg = None
        self.sent: list = []
        self.queue: collections.deque = collections.deque()
        self.on_command = on_command or (lambda msg: [self.ack(msg)])
        self.last_texts: list[str] = []

    def ack(self, msg, result=M.MAV_RESULT_ACCEPTED):
        return _decoded(M.MAVLink_command_ack_message(msg.command, result))

    def send(self, msg) -> None:
        self.sent.append(msg)
        if msg.get_type() == "COMMAND_LONG":
            self.queue.extend(self.on_command(msg))

    def recv(self, types=None, timeout: float = 1.0):
        while self.queue:
            msg = self.queue.popleft()
            if types is None or msg.get_type() in types:
                return msg
        return None

    def command(self, command: int, *params: float, timeout: float = 1.0, retries: int = 3):
        p = [*params, *([0.0] * (7 - len(params)))]
        self.send(M.MAVLink_command_long_message(1, 1, command, 0, *p))
        msg = self.recv(["COMMAND_ACK"])
        assert msg is not None and msg.command == command
        return msg.result

    def describe(self, result: int) -> str:
        return ": ".join([M.enums["MAV_RESULT"][result].name, *self.last_texts])

    def addressed_to_me(self, msg) -> bool:  # as Session's, this station being 255/190
        return getattr(msg, "target_system", 0) in (0, 255) and \
            getattr(msg, "target_component", 0) in (0, 190)

    def from_autopilot(self, msg) -> bool:  # as Session's
        return from_target(msg, self.target_system, self.target_component)

    def commands(self, command: int) -> list:
        return [m for m in self.sent if m.get_type() == "COMMAND_LONG" and m.command == command]


def test_a_mode_is_confirmed_only_by_a_heartbeat_showing_it():
    def engages(mode: int):
        return lambda msg: [Vehicle().ack(msg), _heartbeat(mode)]

    guided = ARDUCOPTER.resolve_mode("GUIDED")
    ok = Vehicle(on_command=engages(4))
    assert commands.set_mode(ok, guided, confirm_s=0.2) == M.MAV_RESULT_ACCEPTED
    sent = ok.commands(M.MAV_CMD_DO_SET_MODE)[0]
    assert (sent.param1, sent.param2, sent.param3) == (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 0)
    other = Vehicle(on_command=engages(5))  # ACCEPTED, then LOITER: not what was asked
    with pytest.raises(commands.NotConfirmed, match="not confirmed: the vehicle is in LOITER"):
        commands.set_mode(other, guided, confirm_s=0.2)
    with pytest.raises(GcsError, match="not confirmed: the vehicle is in LOITER"):
        set_mode(Vehicle(on_command=engages(5)), "guided", confirm_s=0.2)
    silent = Vehicle()
    with pytest.raises(commands.NotConfirmed, match=r"no HEARTBEAT within 0\.2 s"):
        commands.set_mode(silent, guided, confirm_s=0.2)


def test_a_heartbeat_of_another_component_confirms_nothing():
    v = Vehicle(on_command=lambda msg: [Vehicle().ack(msg), _heartbeat(4, component=191)])
    with pytest.raises(commands.NotConfirmed):
        commands.set_mode(v, ARDUCOPTER.resolve_mode("GUIDED"), confirm_s=0.2)


def test_a_refusal_is_returned_unconfirmed():
    v = Vehicle(on_command=lambda msg: [Vehicle().ack(msg, M.MAV_RESULT_DENIED),
                                        _heartbeat(0)])
    assert commands.set_mode(v, ARDUCOPTER.resolve_mode("AUTO"), confirm_s=0.2) == \
        M.MAV_RESULT_DENIED


# ------------------------------------------------------------------ takeoff


def _flying(armed: bool, landed: int, relative_alt_mm: int = 0, mode: int = 0,
            home_alt_mm: int = 584_000,
            takeoff_mode: int = px4_modes.Mode.TAKEOFF.custom_mode,
            copy_refused: int | None = None):
    """A vehicle that answers REQUEST_MESSAGE and engages each DO_SET_MODE. `copy_refused`:
    NAV_TAKEOFF's answer to a copy (the first send's answer lost: `command_sends` 2), the
    vehicle then in the landed state `copy_refused` says (none: TAKEOFF)."""
    state = {"landed": landed}

    def on_command(msg):
        replies = [Vehicle().ack(msg)]
        if msg.command == M.MAV_CMD_NAV_TAKEOFF and copy_refused is not None:
            v.command_sends = 2
            if copy_refused != M.MAV_LANDED_STATE_UNDEFINED:
                state["landed"] = copy_refused
            return [Vehicle().ack(msg, M.MAV_RESULT_FAILED)]
        if msg.command == M.MAV_CMD_REQUEST_MESSAGE:
            if int(msg.param1) == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
                replies.append(_decoded(M.MAVLink_extended_sys_state_message(
                    0, state["landed"])))
            elif int(msg.param1) == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
                replies += [_decoded(M.MAVLink_global_position_int_message(
                    0, 0, 0, home_alt_mm + relative_alt_mm, relative_alt_mm, 0, 0, 0, 0)),
                    _heartbeat(mode, armed, autopilot=v.autopilot_id)]
            elif int(msg.param1) == M.MAVLINK_MSG_ID_HOME_POSITION:
                replies.append(_decoded(M.MAVLink_home_position_message(
                    -353632610, 1491652300, home_alt_mm, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0)))
        elif msg.command == M.MAV_CMD_DO_SET_MODE:
            replies.append(_heartbeat(int(msg.param2), armed, autopilot=v.autopilot_id))
        elif msg.command == M.MAV_CMD_NAV_TAKEOFF and v.autopilot_id == M.MAV_AUTOPILOT_PX4:
            replies.append(_heartbeat(takeoff_mode, armed, autopilot=v.autopilot_id))
        return replies

    v = Vehicle(on_command=on_command)
    v.autopilot_id = M.MAV_AUTOPILOT_ARDUPILOTMEGA
    v.conn = SimpleNamespace(messages={}, recv_match=lambda type=None, blocking=True,
                             timeout=0: v.recv([type] if isinstance(type, str) else type))
    return v


def test_arducopter_takes_off_in_guided_with_a_relative_altitude():
    v = _flying(armed=True, landed=M.MAV_LANDED_STATE_ON_GROUND)
    result, reached = commands.takeoff(v, 10.0, confirm_s=0.2)
    assert result == M.MAV_RESULT_ACCEPTED and reached is None
    modes = v.commands(M.MAV_CMD_DO_SET_MODE)
    takeoffs = v.commands(M.MAV_CMD_NAV_TAKEOFF)
    assert [m.param2 for m in modes] == [4.0] and len(takeoffs) == 1  # GUIDED first
    assert v.sent.index(modes[0]) < v.sent.index(takeoffs[0])
    assert takeoffs[0].param7 == 10.0


def test_px4_takes_off_to_an_amsl_altitude():
    v = _flying(armed=True, landed=M.MAV_LANDED_STATE_ON_GROUND)
    v.autopilot, v.autopilot_id = PX4, M.MAV_AUTOPILOT_PX4
    commands.takeoff(v, 10.0, confirm_s=0.2)
    assert not v.commands(M.MAV_CMD_DO_SET_MODE)
    (takeoff,) = v.commands(M.MAV_CMD_NAV_TAKEOFF)
    assert takeoff.param7 == pytest.approx(594.0)  # home 584 m AMSL + 10 m
    assert math.isnan(takeoff.param5) and math.isnan(takeoff.param6)
    with pytest.raises(ValueError, match="AMSL"):
        commands.takeoff_params(PX4, 10.0, None)
    held = _flying(armed=True, landed=M.MAV_LANDED_STATE_ON_GROUND,
                   takeoff_mode=px4_modes.Mode.HOLD.custom_mode)  # accepted, but stays in HOLD
    held.autopilot, held.autopilot_id = PX4, M.MAV_AUTOPILOT_PX4
    with pytest.raises(commands.NotConfirmed, match="the vehicle is in HOLD"):
        commands.takeoff(held, 10.0, confirm_s=0.2)


@pytest.mark.parametrize(("landed_then", "result"), [
    (M.MAV_LANDED_STATE_TAKEOFF, M.MAV_RESULT_ACCEPTED),
    (M.MAV_LANDED_STATE_IN_AIR, M.MAV_RESULT_ACCEPTED),
    (M.MAV_LANDED_STATE_UNDEFINED, M.MAV_RESULT_FAILED),  # still on the ground
])
def test_a_refused_copy_of_a_takeoff_that_was_taken_is_no_refusal(landed_then, result):
    """The first NAV_TAKEOFF's answer is lost and the copy is refused (ArduCopter, once
    climbing: "can't takeoff again"): when the vehicle then leaves or is off the ground,
    the takeoff was taken; on the ground the refusal stands."""
    v = _flying(armed=True, landed=M.MAV_LANDED_STATE_ON_GROUND, copy_refused=landed_then)
    assert commands.takeoff(v, 10.0, confirm_s=0.2)[0] == result


@pytest.mark.parametrize(("armed", "landed", "rel_mm", "why"), [
    (False, M.MAV_LANDED_STATE_ON_GROUND, 0, "not armed"),
    (True, M.MAV_LANDED_STATE_IN_AIR, 10_000, "in the air"),
    (True, M.MAV_LANDED_STATE_UNDEFINED, 10_000, "in the air"),  # by its height then
])
def test_takeoff_refused_disarmed_or_in_the_air(armed, landed, rel_mm, why):
    v = _flying(armed=armed, landed=landed, relative_alt_mm=rel_mm)
    with pytest.raises(GcsError, match=why):
        commands.takeoff(v, 10.0, confirm_s=0.2, fail=GcsError)
    assert not v.commands(M.MAV_CMD_NAV_TAKEOFF)


def test_takeoff_judges_the_height_above_home_not_above_the_local_origin(monkeypatch):
    """ArduPilot sets its local origin at its first fix and home at arming: with the
    origin 3 m below home, LOCAL_POSITION_NED's -z reads 3 m more than the height above
    home. The wait for a takeoff's height takes GLOBAL_POSITION_INT's relative altitude:
    -z 10.0 m at 7.0 m above home is not 9.5 m reached (it was), 9.6 m above home is; a
    vehicle that sends no GLOBAL_POSITION_INT is judged on -z after LOCAL_FALLBACK_S."""
    def local(up_m: float):
        return _decoded(M.MAVLink_local_position_ned_message(0, 0.0, 0.0, -up_m, 0.0, 0.0, 0.0))

    def above_home(up_m: float):
        return _decoded(M.MAVLink_global_position_int_message(0, 0, 0, 0, round(up_m * 1e3),
                                                              0, 0, 0, 0))

    v = Vehicle()
    v.queue.extend([local(10.0), above_home(7.0), local(10.3)])
    assert commands.wait_height(v, lambda: 9.5, 0.3) is None
    v.queue.extend([local(12.6), above_home(9.6)])
    assert commands.wait_height(v, lambda: 9.5, 0.3) == pytest.approx(9.6)
    monkeypatch.setattr(commands, "LOCAL_FALLBACK_S", 0.0)
    v.queue.extend([local(9.7)])
    assert commands.wait_height(v, lambda: 9.5, 0.3) == pytest.approx(9.7)


# ------------------------------------------------------------------ goto set-points


def test_goto_on_ardupilot_streams_position_and_yaw_only():
    target = PoseTarget.from_euler_deg((10.0, 0.0, -10.0), 0.0, 0.0, 90.0)
    session = SimpleNamespace(target_system=1, target_component=1)
    (pos,) = target.messages(session, attitude=False)
    assert pos.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert pos.type_mask == 0b1001_1111_1000  # velocity, acceleration, yaw rate ignored
    assert not pos.type_mask & 0b111 and not pos.type_mask & (1 << 10)  # position, yaw used
    assert pos.yaw == pytest.approx(math.pi / 2)
    assert [m.get_type() for m in target.messages(session)] == [
        "SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET"]
    # attitude targets only to a vehicle that says it flies both (this FCU's tag)
    assert flies_pose(list(FLIGHT_CUSTOM_VERSION)) and flies_pose(bytes(FLIGHT_CUSTOM_VERSION))
    assert not flies_pose([0] * 8) and not flies_pose(None)
    assert not flies_pose(list(bytes.fromhex("f2471861a0b1c2d3")))  # PX4's git hash
    assert autopilot_version(1).flight_custom_version == list(FLIGHT_CUSTOM_VERSION)
    assert (ARDUCOPTER.guided_mode, PX4.guided_mode) == ("GUIDED", "OFFBOARD")


def test_yaw_error_without_attitude_targets():
    target = PoseTarget.from_euler_deg((0.0, 0.0, -10.0), 0.0, 0.0, 179.0)
    snap = Snapshot()
    snap.update(_decoded(M.MAVLink_local_position_ned_message(0, 0.0, 0.0, -10.0, 0, 0, 0)))
    half = math.radians(-179.0) / 2  # yaw -179 deg: 2 deg from the target, across +-180
    snap.update(_decoded(M.MAVLink_attitude_quaternion_message(
        0, math.cos(half), 0.0, 0.0, math.sin(half), 0, 0, 0)))
    dp, dyaw = pose_errors(snap, target, attitude=False)
    assert dp == pytest.approx(0.0) and dyaw == pytest.approx(math.radians(2.0), abs=1e-6)


# ------------------------------------------------------------------ telemetry requests


class Streaming(Vehicle):
    """Answers GET/SET_MESSAGE_INTERVAL from its own table (id -> us; -1 off); `set_ok`
    False refuses every SET (an old ArduPilot)."""

    def __init__(self, table: dict[int, int], autopilot=ARDUCOPTER, set_ok: bool = True):
        super().__init__(autopilot, self._answer)
        self.table = dict(table)
        self.set_ok = set_ok

    def _answer(self, msg):
        msg_id = int(msg.param1)
        if msg.command == M.MAV_CMD_GET_MESSAGE_INTERVAL:
            return [_decoded(M.MAVLink_message_interval_message(msg_id, self.table.get(msg_id,
                                                                                       0))),
                    self.ack(msg)]
        if msg.command == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            if not self.set_ok:
                return [self.ack(msg, M.MAV_RESULT_UNSUPPORTED)]
            self.table[msg_id] = int(msg.param2)
            return [self.ack(msg)]
        return [self.ack(msg)]


POS, ATT, SYS = (M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
                 M.MAVLINK_MSG_ID_SYS_STATUS)


def test_streams_are_asked_for_and_given_back():
    v = Streaming({POS: -1, ATT: 20_000, SYS: 2_000_000})  # off, 50 Hz, 0.5 Hz
    changed = streams.request(v, {"LOCAL_POSITION_NED": 10.0, "ATTITUDE_QUATERNION": 10.0,
                                  "SYS_STATUS": 2.0})
    assert v.table == {POS: 100_000, ATT: 20_000, SYS: 500_000}  # the fast one untouched
    assert changed.changed == {POS: -1, SYS: 2_000_000}
    streams.restore(v, changed)
    assert v.table == {POS: -1, ATT: 20_000, SYS: 2_000_000}
    sets = v.commands(M.MAV_CMD_SET_MESSAGE_INTERVAL)
    assert {int(m.param1) for m in sets} == {POS, SYS}  # ATTITUDE was never touched


def test_a_stream_the_vehicle_lacks_is_not_asked_for():
    v = Streaming({POS: 0})  # "not available"
    assert streams.request(v, {"LOCAL_POSITION_NED": 10.0}).changed == {}
    assert not v.commands(M.MAV_CMD_SET_MESSAGE_INTERVAL)


def test_a_px4_stream_read_as_0_is_asked_for_and_stopped_again():
    """PX4 answers GET_MESSAGE_INTERVAL with 0 for any stream it is not sending on the link
    (its MavlinkReceiver::get_message_interval), and SET_MESSAGE_INTERVAL starts it: a PX4
    vehicle's 0 is asked for, and stopped again (-1) on leaving; ArduPilot's 0 is "not
    available" (the test above)."""
    v = Streaming({POS: 0}, autopilot=PX4)
    changed = streams.request(v, {"LOCAL_POSITION_NED": 10.0})
    assert v.table == {POS: 100_000} and changed.changed == {POS: 0}
    streams.restore(v, changed)
    assert v.table == {POS: -1}


def test_ardupilot_without_set_message_interval_gets_data_streams():
    v = Streaming({POS: -1, SYS: -1}, set_ok=False)
    changed = streams.request(v, {"LOCAL_POSITION_NED": 10.0, "SYS_STATUS": 2.0})
    asked = [m for m in v.sent if m.get_type() == "REQUEST_DATA_STREAM"]
    assert {(m.req_stream_id, m.req_message_rate, m.start_stop) for m in asked} == {
        (M.MAV_DATA_STREAM_POSITION, 10, 1), (M.MAV_DATA_STREAM_EXTENDED_STATUS, 2, 1)}
    streams.restore(v, changed)
    stopped = [m for m in v.sent if m.get_type() == "REQUEST_DATA_STREAM"][len(asked):]
    assert {(m.req_stream_id, m.start_stop) for m in stopped} == {
        (M.MAV_DATA_STREAM_POSITION, 0), (M.MAV_DATA_STREAM_EXTENDED_STATUS, 0)}
    px4 = Streaming({POS: -1}, autopilot=PX4, set_ok=False)  # PX4 has no such fallback
    streams.request(px4, {"LOCAL_POSITION_NED": 10.0})
    assert not [m for m in px4.sent if m.get_type() == "REQUEST_DATA_STREAM"]


def test_each_command_asks_for_what_it_shows():
    assert "EKF_STATUS_REPORT" in streams.needs("status", "ardupilot")
    assert "EKF_STATUS_REPORT" not in streams.needs("status", "px4")
    assert {"LOCAL_POSITION_NED", "ATTITUDE_QUATERNION"} <= set(streams.needs("goto", "px4"))
    assert streams.needs("mode", "ardupilot") == {}


# ------------------------------------------------------------------ health and readiness


def _sys_status(present: int, enabled: int, healthy: int):
    return SimpleNamespace(onboard_control_sensors_present=present,
                           onboard_control_sensors_enabled=enabled,
                           onboard_control_sensors_health=healthy)


def test_health_counts_enabled_sensors_only():
    # ArduCopter 4.7 on the ground, ready to arm (observed): the position controllers are
    # present but not enabled, and not healthy
    ready = _sys_status(0x5371FC2F, 0x52619C2F, 0x57719C2F)
    assert health.health(ready) == "ok"
    gps = M.MAV_SYS_STATUS_SENSOR_GPS
    bad = _sys_status(0x5371FC2F, 0x52619C2F, 0x57719C2F & ~gps)
    assert health.health(bad) == "unhealthy sensors: GPS"
    not_ready = _sys_status(0x5371FC2F, 0x52619C2F, 0x57719C2F & ~health.PREARM)
    assert health.health(not_ready) == "ok"  # readiness, not health
    assert health.readiness(not_ready, None, ["PreArm: Need Position Estimate", "x"]) == {
        "ready_to_arm": False, "reasons": ["PreArm: Need Position Estimate"]}
    assert health.readiness(ready, None, [])["ready_to_arm"] is True
    assert health.readiness(_sys_status(0x3, 0x3, 0x3), None, [])["ready_to_arm"] is None


def test_ekf_state():
    assert health.ekf_state(831) == "ok"  # ArduCopter ready to arm (observed)
    assert health.ekf_state(831 & ~16) == "no horizontal position"
    assert health.ekf_state(831 | 128) == "constant position mode"
    ekf = SimpleNamespace(flags=831 & ~16)
    value = health.readiness(None, ekf, [])
    assert value == {"ready_to_arm": None, "ekf": "no horizontal position"}
    assert health.format_readiness(value) == "unknown, EKF no horizontal position"
    assert health.format_readiness({"ready_to_arm": True, "ekf": "ok"}) == \
        "ready to arm, EKF ok"


def test_status_names_modes_in_the_autopilots_spelling():
    assert heartbeat_mode(_heartbeat(17)) == "BRAKE"
    assert heartbeat_mode(_heartbeat(px4_modes.Mode.HOLD.custom_mode,
                                        autopilot=M.MAV_AUTOPILOT_PX4)) == "HOLD"
    assert mode_name(px4_modes.Mode.OFFBOARD.custom_mode, M.MAV_AUTOPILOT_GENERIC) == \
        "OFFBOARD"
    assert mode_name(5, M.MAV_AUTOPILOT_ARDUPILOTMEGA, M.MAV_TYPE_HEXAROTOR) == "LOITER"
    assert PX4.mode_name(1 << 16) == "MANUAL"
