"""The station's waiting policy (`gcs.vehicle_link.patience`) against a scripted vehicle on loopback
UDP: a vehicle that is busy but heard (its heartbeats go on) is waited for, past the protocols'
timeouts, up to the ceiling; a vehicle that falls silent is given up on after the silence
limit, not the ceiling, and the error says which."""

from __future__ import annotations

import threading
import time

import pytest

from common.wire.mavlink import MAV
from common.wire.mission_items import MissionItem
from gcs.vehicle_link.mission_client import MissionError, upload_detailed
from gcs.vehicle_link.params import param_set
from gcs.vehicle_link.patience import MISSION_ITEM, SILENCE_S, Budget, Wait
from gcs.vehicle_link.session import GcsError, Session
from tests.unit.scripted_autopilot import Companion, ScriptedAutopilot

M = MAV
REAL32 = M.MAV_PARAM_TYPE_REAL32
SLOW_S = 2.0  # how long the busy vehicle takes to answer: past every protocol timeout


class BusyVehicle(ScriptedAutopilot):
    """A vehicle whose heartbeats go on (10 Hz) while it takes `slow_s` to answer the last
    mission item, a PARAM_SET or a COMMAND_LONG; with `silent_on` ("item", "param",
    "command") it stops sending anything at all when that request comes."""

    def __init__(self, slow_s: float = 0.0, silent_on: str = "") -> None:
        self.slow_s = slow_s
        self.silent_on = silent_on
        self.silent = False
        self.commands_heard: list[int] = []  # confirmation of each COMMAND_LONG
        self.items_heard = 0
        self.param_sets_heard = 0
        self.acks_sent = 0
        self._answered: set[str] = set()
        self._timers: list[threading.Timer] = []
        self._lock = threading.Lock()
        super().__init__("px4", params={"MIS_CRUISE_SPD": (5.0, REAL32)})

    def _send(self, msg) -> None:
        with self._lock:
            if not self.silent:
                super()._send(msg)

    def _later(self, key: str, answer) -> None:
        """`answer()` once, `slow_s` after the first request (repeats are not acted on)."""
        if key in self._answered:
            return
        self._answered.add(key)
        timer = threading.Timer(self.slow_s, answer)
        self._timers.append(timer)
        timer.start()

    def close(self) -> None:
        """Answers not yet due are dropped (their socket closes with the vehicle)."""
        for timer in self._timers:
            timer.cancel()
            timer.join(timeout=5.0)
        super().close()

    def _item(self, item: MissionItem) -> None:
        self.items_heard += 1
        last = self._upload is not None and item.seq == self._count - 1 == len(self._upload)
        if last and self.silent_on == "item":
            self.silent = True
            return
        if last:
            self._upload.append(item)
            mission, self._upload = self._upload, None

            def accept() -> None:
                self.mission = mission
                self.acks_sent += 1
                self._send(M.MAVLink_mission_ack_message(255, 0, M.MAV_MISSION_ACCEPTED, 0))

            self._later("mission", accept)
            return
        if "mission" in self._answered and not self.acks_sent:
            return  # busy with the last item: a repeat waits (a firmware's one loop)
        super()._item(item)

    def _param_set(self, msg) -> None:
        self.param_sets_heard += 1
        if self.silent_on == "param":
            self.silent = True
            return
        self._later("param", lambda: ScriptedAutopilot._param_set(self, msg))

    def _command(self, msg) -> None:
        self.commands_heard.append(msg.confirmation)
        if self.silent_on == "command":
            self.silent = True
            return
        self._later("command", lambda: self._send(
            M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_ACCEPTED)))


def _items(n: int = 3) -> list[MissionItem]:
    return [MissionItem(i, 1, 16, int(i == 0), 1, 0, 0, 0, 0, 0, 0, -2.0) for i in range(n)]


@pytest.fixture
def connected():
    made: list[tuple[BusyVehicle, Session]] = []

    def make(**kw) -> tuple[BusyVehicle, Session]:
        v = BusyVehicle(**kw)
        s = Session(v.url, heartbeat_hz=5.0)
        made.append((v, s))
        s.wait_vehicle(timeout=5.0)
        return v, s

    yield make
    for v, s in made:
        s.close()
        v.close()


def _upload(s: Session):
    return upload_detailed(s.conn, s.target_system, s.target_component, _items(),
                           send=s.send)


# ------------------------------------------------------------------ the policy itself

def test_a_wait_ends_on_silence_or_at_its_ceiling_and_says_which():
    b = Budget(resend_s=0.25, ceiling_s=30.0, silence_s=3.0)
    w = Wait(b, now=100.0)
    assert w.expired(now=102.9) == "" and w.due(now=100.3) and not w.due(now=100.2)
    assert w.expired(now=103.0) == ": vehicle silent for 3.0 s"
    for t in range(101, 131):  # heard every second: only the ceiling ends it
        w.heard(now=float(t))
        if t < 130:
            assert w.expired(now=float(t)) == ""
    assert w.expired(now=130.0) == " within the 30 s ceiling"
    assert 0.0 < w.left(now=100.1) <= 0.15 + 1e-9  # the next re-send is the next thing to do
    w.stop_resending()
    assert not w.due(now=200.0)


# ------------------------------------------------------------------ missions

def test_a_busy_vehicle_answering_the_last_item_after_2_s_gets_its_mission(connected):
    """Given a vehicle that answers the last item only after 2 s (eight item timeouts) while
    its heartbeats go on, then the upload succeeds: the last item was re-sent meanwhile
    and the vehicle, acting once, holds the mission."""
    v, s = connected(slow_s=SLOW_S)
    t0 = time.monotonic()
    answer = _upload(s)
    took = time.monotonic() - t0
    assert answer.result == M.MAV_MISSION_ACCEPTED
    assert len(v.mission) == 3 and v.acks_sent == 1
    assert SLOW_S <= took < SLOW_S + 2.0
    assert v.items_heard > 3  # the last item re-sent as the spec says


def test_a_vehicle_that_falls_silent_fails_the_upload_after_the_silence_limit(connected):
    """Given a vehicle that stops sending anything when the last item comes, then the upload
    fails saying the vehicle was silent for 3.0 s, in about that time, not the ceiling's."""
    _v, s = connected(silent_on="item")
    t0 = time.monotonic()
    with pytest.raises(MissionError, match=r"no MISSION_ACK after the last item \(2\): "
                       r"vehicle silent for 3\.0 s \([0-9]+ tries, 250 ms apart\); the "
                       r"vehicle may hold the new mission"):
        _upload(s)
    took = time.monotonic() - t0
    assert SILENCE_S <= took < SILENCE_S + 1.5 < MISSION_ITEM.ceiling_s


def test_a_companion_heartbeat_does_not_keep_a_silent_autopilot_heard(connected):
    """Given an autopilot that stops sending anything when the last item comes while a
    companion computer of its system (component 191) goes on sending HEARTBEAT, then the
    upload still fails on silence after 3.0 s: only the autopilot counts. (The companion
    used to keep the wait going to its 30 s ceiling.)"""
    v, s = connected(silent_on="item")
    t0 = time.monotonic()
    with Companion(v), pytest.raises(MissionError, match=r"vehicle silent for 3\.0 s"):
        _upload(s)
    assert SILENCE_S <= time.monotonic() - t0 < SILENCE_S + 1.5


def test_a_heard_vehicle_that_never_answers_fails_at_the_ceiling(connected):
    """Given a vehicle heard throughout that never answers the last item, then the upload
    fails at the ceiling, saying so (the silence limit set far beyond it: a thread of the
    scripted vehicle starved for 3 s on a busy machine is silence, rightly)."""
    _v, s = connected(slow_s=60.0)
    t0 = time.monotonic()
    with pytest.raises(MissionError, match=r"no MISSION_ACK after the last item \(2\) within "
                       r"the 1\.5 s ceiling"):
        upload_detailed(s.conn, s.target_system, s.target_component, _items(), send=s.send,
                        ceiling_s=1.5, silence_s=60.0)
    assert 1.5 <= time.monotonic() - t0 < 10.0  # the ceiling, not the vehicle's 60 s


# ------------------------------------------------------------------ parameters

def test_a_busy_vehicle_setting_a_parameter_for_2_s_is_waited_for(connected):
    v, s = connected(slow_s=SLOW_S)
    t0 = time.monotonic()
    value, _texts = param_set(s, "MIS_CRUISE_SPD", 3.5, param_type=REAL32)
    assert value == 3.5 and v.params["MIS_CRUISE_SPD"][0] == 3.5
    assert SLOW_S <= time.monotonic() - t0 < SLOW_S + 2.0
    # PARAM_SET re-sent meanwhile (the same value), acted on once
    assert v.param_sets_heard >= 2 and len(v.param_sets) == 1


def test_a_parameter_set_to_a_silent_vehicle_fails_after_the_silence_limit(connected):
    _v, s = connected(silent_on="param")
    t0 = time.monotonic()
    with pytest.raises(GcsError, match=r"parameter MIS_CRUISE_SPD not answered: vehicle "
                       r"silent for 3\.0 s"):
        param_set(s, "MIS_CRUISE_SPD", 3.5, param_type=REAL32)
    assert SILENCE_S <= time.monotonic() - t0 < SILENCE_S + 1.5


# ------------------------------------------------------------------ commands

def test_a_busy_vehicle_acking_a_command_after_2_s_is_waited_for(connected):
    """Given a vehicle that acknowledges a command 2 s after it first came, then the command
    is ACCEPTED; the re-sends meanwhile carry an incremented confirmation (so the vehicle
    can tell them from a new command) and it acted once."""
    v, s = connected(slow_s=SLOW_S)
    t0 = time.monotonic()
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
    assert SLOW_S <= time.monotonic() - t0 < SLOW_S + 2.0
    assert v.commands_heard[:3] == [0, 1, 2][:len(v.commands_heard[:3])]
    assert len(v.commands_heard) >= 2


def test_a_command_to_a_silent_vehicle_fails_after_the_silence_limit(connected):
    _v, s = connected(silent_on="command")
    t0 = time.monotonic()
    with pytest.raises(GcsError, match=r"no COMMAND_ACK for command 400: vehicle silent for "
                       r"3\.0 s"):
        s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert SILENCE_S <= time.monotonic() - t0 < SILENCE_S + 1.5


def test_in_progress_stops_the_resends_and_waits_for_the_final_answer(connected):
    v, s = connected()

    def in_progress(msg) -> None:
        v.commands_heard.append(msg.confirmation)
        if len(v.commands_heard) == 1:
            v._send(M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_IN_PROGRESS))
            threading.Timer(SLOW_S, lambda: v._send(M.MAVLink_command_ack_message(
                msg.command, M.MAV_RESULT_ACCEPTED))).start()

    v._command = in_progress  # type: ignore[method-assign]
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == M.MAV_RESULT_ACCEPTED
    assert v.commands_heard == [0]  # never sent again once the vehicle said it works on it


def test_a_command_ack_to_another_station_is_not_the_answer(connected):
    """Given a vehicle that answers another station (254/190) on the same link, its
    COMMAND_ACK addressed there (DENIED, or IN_PROGRESS) before ours, then the command's
    answer is the one addressed to this station (ACCEPTED); the other's IN_PROGRESS does
    not stop our re-sends. (Any ACK of the command used to be taken.)"""
    v, s = connected()
    arm = M.MAV_CMD_COMPONENT_ARM_DISARM

    def shared_link(msg) -> None:
        v.commands_heard.append(msg.confirmation)
        v._send(M.MAVLink_command_ack_message(arm, M.MAV_RESULT_DENIED, 0, 0, 254, 190))
        v._send(M.MAVLink_command_ack_message(arm, M.MAV_RESULT_IN_PROGRESS, 0, 0, 254, 190))
        if len(v.commands_heard) == 2:  # our re-send is answered
            threading.Timer(0.2, lambda: v._send(M.MAVLink_command_ack_message(
                arm, M.MAV_RESULT_ACCEPTED, 0, 0, s.conn.mav.srcSystem,
                s.conn.mav.srcComponent))).start()

    v._command = shared_link  # type: ignore[method-assign]
    assert s.command(arm, 1.0) == M.MAV_RESULT_ACCEPTED
    assert v.commands_heard[:2] == [0, 1]  # re-sent (a third on a slow machine is fine)


def test_a_command_left_in_progress_says_so_at_the_ceiling(connected):
    """Given a vehicle that answers IN_PROGRESS and never the final result, then the command
    fails at its ceiling saying no final COMMAND_ACK came, the last being IN_PROGRESS."""
    v, s = connected()
    v._command = lambda msg: v._send(M.MAVLink_command_ack_message(  # type: ignore[method-assign]
        msg.command, M.MAV_RESULT_IN_PROGRESS))
    with pytest.raises(GcsError, match=r"no final COMMAND_ACK for command 400 within the "
                       r"1\.5 s ceiling.*\(the last: MAV_RESULT_IN_PROGRESS\)"):
        s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, ceiling_s=1.5)


# ------------------------------------------------------------------ only the autopilot is heard

def test_a_command_to_a_silent_autopilot_fails_on_silence_beside_a_companion(connected):
    """Given an autopilot that stops sending anything when a command comes, while a
    companion computer of its system goes on with its HEARTBEAT, then the command fails
    on silence after 3.0 s, not at its 10 s ceiling."""
    v, s = connected(silent_on="command")
    t0 = time.monotonic()
    with Companion(v), pytest.raises(GcsError, match=r"no COMMAND_ACK for command 400: "
                                     r"vehicle silent for 3\.0 s"):
        s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
    assert SILENCE_S <= time.monotonic() - t0 < SILENCE_S + 1.5


def test_a_mode_of_an_autopilot_silent_after_its_ack_fails_on_silence_beside_a_companion(
        connected):
    """Given an autopilot that accepts a mode change and then falls silent, while a
    companion's HEARTBEAT goes on, then the mode is not confirmed, for silence after
    3.0 s, not at the confirmation's 10 s ceiling."""
    from gcs.autopilot.commands import NotConfirmed, set_mode
    from gcs.autopilot.dialect import ModeTarget
    v, s = connected()

    def accept_then_fall_silent(msg) -> None:
        v._send(M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_ACCEPTED))
        v.silent = True

    v._command = accept_then_fall_silent  # type: ignore[method-assign]
    t0 = time.monotonic()
    with Companion(v), pytest.raises(NotConfirmed, match=r"vehicle silent for 3\.0 s"):
        set_mode(s, ModeTarget("POSCTL", 3 << 16), confirm_s=10.0)
    assert SILENCE_S <= time.monotonic() - t0 < SILENCE_S + 1.5


def test_a_parameter_list_of_a_silent_autopilot_fails_on_silence_beside_a_companion(
        connected):
    """Given an autopilot that falls silent when asked for its parameter list, while a
    companion's HEARTBEAT goes on, then the list fails on silence after 3.0 s, not at its
    10 s ceiling."""
    from gcs.vehicle_link.params import param_values
    v, s = connected()

    def fall_silent(kind, msg) -> None:
        v.silent = True

    v._param_message = fall_silent  # type: ignore[method-assign]
    t0 = time.monotonic()
    with Companion(v), pytest.raises(GcsError, match=r"no PARAM_VALUE answered "
                                     r"PARAM_REQUEST_LIST: vehicle silent for 3\.0 s"):
        param_values(s)
    assert SILENCE_S <= time.monotonic() - t0 < SILENCE_S + 1.5


def test_each_in_progress_restarts_the_commands_ceiling(connected):
    """Given a vehicle that answers IN_PROGRESS every 0.5 s for 3 s, then ACCEPTED, then a
    command with a 1.5 s ceiling is ACCEPTED: progress restarts the ceiling (as MAVSDK
    counts it); it was given up at 1.5 s."""
    v, s = connected()

    def progress(msg) -> None:
        v.commands_heard.append(msg.confirmation)
        for k in range(7):
            threading.Timer(0.5 * k, lambda k=k: v._send(M.MAVLink_command_ack_message(
                msg.command, M.MAV_RESULT_IN_PROGRESS, 16 * k))).start()
        threading.Timer(3.2, lambda: v._send(M.MAVLink_command_ack_message(
            msg.command, M.MAV_RESULT_ACCEPTED))).start()

    v._command = progress  # type: ignore[method-assign]
    t0 = time.monotonic()
    assert s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, ceiling_s=1.5) == \
        M.MAV_RESULT_ACCEPTED
    assert time.monotonic() - t0 >= 3.0 and v.commands_heard == [0]
