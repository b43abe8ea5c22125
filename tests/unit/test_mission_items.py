"""Mission items <-> MAVLink mission messages (common/wire/mission_items.py): the one conversion
that the vehicle, the ground station and the mission files share."""

from __future__ import annotations

import math

import pytest

from common.wire.mavlink import MAV, encoder, pack, parser
from common.wire.mission_items import (
    GLOBAL_FRAMES,
    GLOBAL_SCALE,
    INT32_MAX,
    LOCAL_SCALE,
    MissionItem,
    item_from_message,
    local_xy,
    xy_scale,
)
from common.wire.mission_messages import item_message
from fcu.edge import mission_protocol
from gcs.vehicle_link import mission_client

M = MAV
SRC = (255, M.MAV_COMP_ID_MISSIONPLANNER)


def wire(msg):
    return parser().decode(bytearray(pack(encoder(*SRC), msg)))


def test_global_frames_are_pymavlinks():
    """Given the global frames written out as numbers, then they are common.xml's."""
    assert GLOBAL_FRAMES == {M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                             M.MAV_FRAME_GLOBAL_INT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                             M.MAV_FRAME_GLOBAL_TERRAIN_ALT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT}
    assert xy_scale(M.MAV_FRAME_LOCAL_NED) == LOCAL_SCALE
    assert xy_scale(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT) == GLOBAL_SCALE


def test_item_round_trip_through_the_wire():
    """Given an item, when sent as MISSION_ITEM_INT and decoded, then it comes back equal;
    `current` can be overridden."""
    it = MissionItem(4, M.MAV_FRAME_LOCAL_NED, 31000, 0, 1, 2.5, 0.125, -0.25, 0.5,
                     local_xy(-1.25), local_xy(3.5), -2.0, M.MAV_MISSION_TYPE_MISSION)
    msg = wire(item_message(it, 1, 1))
    assert msg.get_type() == "MISSION_ITEM_INT" and (msg.target_system, msg.seq) == (1, 4)
    assert item_from_message(msg) == it
    assert wire(item_message(it, 1, 1, current=1)).current == 1


@pytest.mark.parametrize(("frame", "x", "want"), [
    (M.MAV_FRAME_LOCAL_NED, 1.5, 15000),
    (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, 47.25, 472500000),
    (M.MAV_FRAME_LOCAL_NED, math.nan, INT32_MAX + 1),
    (M.MAV_FRAME_LOCAL_NED, 3e5, INT32_MAX + 1),
])
def test_legacy_item_scaled_by_frame(frame, x, want):
    """Given a legacy MISSION_ITEM (float x, y), then x, y are scaled by the frame's unit;
    one that is not finite or does not fit int32 becomes INT32_MAX + 1 (refused later)."""
    msg = wire(M.MAVLink_mission_item_message(1, 1, 0, frame, 16, 1, 1, 0.0, 0.0, 0.0, 0.0,
                                              x, 0.0, -2.0, 0))
    item = item_from_message(msg)
    assert item.x == want and item.y == 0
    assert item.xy_fit_int32 == (want <= INT32_MAX)


def test_vehicle_and_ground_station_share_the_conversion():
    """The vehicle side and the ground station use this module's conversion."""
    assert mission_protocol.item_from_message is item_from_message
    assert mission_protocol.item_message is item_message
    assert mission_client.item_from_message is item_from_message
    assert mission_client.item_message is item_message
