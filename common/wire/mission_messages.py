"""The MISSION_ITEM_INT message that carries a mission item (`common.wire.mission_items`): the
one place an item becomes a pymavlink message, on the vehicle's and the station's side alike."""

from __future__ import annotations

from typing import Any

from common.wire.mavlink import MAV
from common.wire.mission_items import MissionItem


def item_message(item: MissionItem, target_system: int, target_component: int,
                 current: int | None = None) -> Any:
    """The MISSION_ITEM_INT that carries `item` (`current` overrides the item's flag)."""
    return MAV.MAVLink_mission_item_int_message(
        target_system, target_component, item.seq, item.frame, item.command,
        item.current if current is None else current, item.autocontinue, item.param1,
        item.param2, item.param3, item.param4, item.x, item.y, item.z, item.mission_type)
