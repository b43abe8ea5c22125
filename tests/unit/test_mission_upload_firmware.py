"""A mission upload against each firmware's answers to items it did not ask for
(tests/unit/scripted_autopilot.py): over a link slower than the station's item re-send, and
with the vehicle's final MISSION_ACK lost. ArduPilot NACKs a re-sent item
(MAV_MISSION_INVALID_SEQUENCE during its upload, MAV_MISSION_ERROR after it); PX4 ignores it,
or answers the last item again."""

from __future__ import annotations

import pytest

from common.wire.mavlink import MAV
from gcs.vehicle_link.mission_client import MissionError, upload_detailed
from gcs.vehicle_link.session import Session
from tests.unit.scripted_autopilot import PLAN_HOME_ITEMS, ScriptedAutopilot, gcs

M = MAV
pytestmark = pytest.mark.timeout(60)


def _upload(v: ScriptedAutopilot):
    s = Session(v.url, heartbeat_hz=5.0)
    try:
        s.wait_vehicle(timeout=5.0)
        return upload_detailed(s.conn, s.target_system, s.target_component,
                               PLAN_HOME_ITEMS, send=s.send)
    finally:
        s.close()


@pytest.mark.parametrize("kind", ["ardupilot", "px4"])
def test_an_upload_over_a_slow_link_is_taken(kind):
    """Given a vehicle whose answers take 400 ms (a round trip above the station's 250 ms
    item re-send), when 4 items are uploaded, then the vehicle takes them and the answer is
    ACCEPTED: the items the station sent again were answered as the firmware answers them
    (ArduPilot's MAV_MISSION_INVALID_SEQUENCE used to end the upload as a refusal)."""
    v = ScriptedAutopilot(kind, reply_delay_s=0.4)
    try:
        answer = _upload(v)
    finally:
        v.close()
    assert answer.result == M.MAV_MISSION_ACCEPTED, answer.describe()
    assert v.mission == list(PLAN_HOME_ITEMS) and v.unasked_items > 0


def test_a_lost_final_ack_from_ardupilot_is_an_unknown_outcome_not_a_refusal():
    """Given ArduPilot losing its MISSION_ACK ACCEPTED, when the station sends the last item
    again, then ArduPilot's MAV_MISSION_ERROR to it (its upload is over) ends the upload as
    unknown, saying the vehicle may hold the new mission, which it does; PX4 answers the
    last item again and the upload is ACCEPTED. (The ERROR used to be taken as a refusal,
    and `gcs mission upload` then put the old mission back over the new one.)"""
    v = ScriptedAutopilot("ardupilot", lose_upload_acks=1)
    try:
        with pytest.raises(MissionError, match="may hold the new mission") as err:
            _upload(v)
        assert "MAV_MISSION_ERROR" in str(err.value)
        assert v.mission == list(PLAN_HOME_ITEMS)
    finally:
        v.close()
    px4 = ScriptedAutopilot("px4", lose_upload_acks=1)
    try:
        assert _upload(px4).result == M.MAV_MISSION_ACCEPTED
        assert px4.mission == list(PLAN_HOME_ITEMS)
    finally:
        px4.close()


def test_gcs_mission_upload_to_ardupilot_over_a_slow_link_exits_0(capsys):
    """`gcs mission upload` of QGC's plan to ArduPilot over a 400 ms link: exit 0, the
    vehicle holds home and the 5 items."""
    from tests.unit.test_mission_home import PLAN
    v = ScriptedAutopilot("ardupilot", reply_delay_s=0.4)
    try:
        code, out, err = gcs(capsys, v, "mission", "upload", str(PLAN))
    finally:
        v.close()
    assert code == 0, out + err
    assert "upload of 5 items: MAV_MISSION_ACCEPTED" in out and len(v.mission) == 6
