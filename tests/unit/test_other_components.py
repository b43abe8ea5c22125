"""Only the autopilot speaks for the vehicle: a scripted vehicle on loopback UDP shares its
link with a companion computer of its system (component 191, as a router merges it in),
which sends its own HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER, mode 0), ATTITUDE, PARAM_VALUE
and COMMAND_ACK. None of them is taken for the autopilot's state, parameters or answers.
(Before, any component of the system was: the companion's HEARTBEAT became the vehicle's
mode in `gcs status` and ended `gcs goto` as "the vehicle left OFFBOARD".)"""

from __future__ import annotations

import time

import pytest

from common.wire.mavlink import MAV
from gcs.vehicle_link.session import Session
from tests.unit.scripted_autopilot import Companion, ScriptedAutopilot, _RawParamValue, gcs

M = MAV
REAL32 = M.MAV_PARAM_TYPE_REAL32
PARAMS = {f"AP_{i:02d}": (float(i), REAL32) for i in range(12)}
pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def vehicle():
    v = ScriptedAutopilot("px4", params=PARAMS)
    yield v
    v.close()


def _session(v: ScriptedAutopilot) -> Session:
    s = Session(v.url, heartbeat_hz=5.0)
    s.wait_vehicle(timeout=5.0)
    return s


def test_status_shows_the_autopilot_not_its_companion(vehicle):
    """Given a companion that sends HEARTBEAT and ATTITUDE at 20 Hz beside the autopilot
    (which sends no ATTITUDE), then the status is the autopilot's: a hexarotor, and no
    attitude."""
    from gcs.vehicle_link.status import status
    with Companion(vehicle, (M.MAVLink_attitude_message(0, 1.0, 0.5, 0.25, 0, 0, 0),),
                   period_s=0.05):
        s = _session(vehicle)
        try:
            out = status(s, seconds=0.6, patience=0.5)
        finally:
            s.close()
    assert (out["component"], out["type"]) == (1, "MAV_TYPE_HEXAROTOR")
    assert "roll_pitch_yaw_deg" not in out


class LosesIndex5(ScriptedAutopilot):
    """Its PARAM_REQUEST_LIST answer loses index 5 (read by index, it comes)."""

    def _param_message(self, kind: str, msg) -> None:
        if kind == "PARAM_REQUEST_LIST":
            for i in range(len(self.names)):
                if i != 5:
                    self._param_value(i)
        else:
            super()._param_message(kind, msg)


def test_param_list_holds_the_autopilots_parameters_only(capsys):
    """Given a companion that sends its own two parameters (param_count 2) every 2 ms all
    through the autopilot's list, which loses index 5, then `gcs param list` prints the
    autopilot's twelve, in order, in less than the list's 10 s ceiling: the companion's
    values do not mix in."""
    own = tuple(_RawParamValue(f"CC_{i}", b"\0\0\0\0", REAL32, 2, i) for i in range(2))
    v = LosesIndex5("px4", params=PARAMS)
    try:
        t0 = time.monotonic()
        with Companion(v, own, period_s=0.002):
            code, out, err = gcs(capsys, v, "param", "list")
        took = time.monotonic() - t0
    finally:
        v.close()
    assert code == 0, err
    assert [line.split()[0] for line in out.splitlines()] == list(PARAMS)
    assert took < 8.0


def test_a_cameras_heartbeat_is_not_taken_for_the_vehicle():
    """Given a camera of the vehicle's system whose HEARTBEAT (every 5 ms) announces an
    autopilot, as some have, and comes before the autopilot's (everything the autopilot
    sends is 0.3 s late), then the station takes the autopilot (component 1) for the
    vehicle."""
    camera = M.MAVLink_heartbeat_message(M.MAV_TYPE_CAMERA, M.MAV_AUTOPILOT_PX4, 0, 0,
                                         M.MAV_STATE_ACTIVE, 3)
    v = ScriptedAutopilot("px4", reply_delay_s=0.3)
    try:
        with Companion(v, (camera,), period_s=0.005, component=100):
            s = Session(v.url, heartbeat_hz=50.0)
            try:
                s.wait_vehicle(timeout=5.0)
                assert (s.target_component, s.heartbeat_msg.type) == \
                    (1, M.MAV_TYPE_HEXAROTOR)
            finally:
                s.close()
    finally:
        v.close()


def test_a_companions_command_ack_is_not_the_autopilots_answer():
    """Given a companion that keeps answering the arm command DENIED (to any station,
    target 0) while the autopilot's ACCEPTED comes 0.3 s later, then the command's answer
    is ACCEPTED."""
    arm = M.MAV_CMD_COMPONENT_ARM_DISARM
    deny = M.MAVLink_command_ack_message(arm, M.MAV_RESULT_DENIED, 0, 0, 0, 0)
    v = ScriptedAutopilot("px4", reply_delay_s=0.3)
    try:
        with Companion(v, (deny,), period_s=0.01):
            s = _session(v)
            try:
                assert s.command(arm, 1.0) == M.MAV_RESULT_ACCEPTED
            finally:
                s.close()
    finally:
        v.close()
