"""Mission items as MISSION_ITEM_INT carries them (local frames: x, y in 1e-4 m), and the one
conversion between items and MAVLink mission messages (vehicle and ground station alike).

x and y of MISSION_ITEM_INT are int32: metres x 1e4 in local frames, degrees x 1e7 in global
ones (MAVLink's common.xml); the legacy MISSION_ITEM carries them as floats in metres or
degrees. pymavlink is imported only by `item_message`, so that the flight code can use
`MissionItem` without a MAVLink library.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

LOCAL_SCALE = 1e4  # MISSION_ITEM_INT x, y in local frames: metres x 1e4
GLOBAL_SCALE = 1e7  # MISSION_ITEM_INT x, y in global frames: degrees x 1e7
INT32_MIN, INT32_MAX = -(2 ** 31), 2 ** 31 - 1
MAV_MISSION_TYPE_MISSION = 0
# MAV_FRAME_GLOBAL, _GLOBAL_RELATIVE_ALT, _GLOBAL_INT, _GLOBAL_RELATIVE_ALT_INT,
# _GLOBAL_TERRAIN_ALT, _GLOBAL_TERRAIN_ALT_INT (common.xml; checked against pymavlink).
GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})


class MissionItem(NamedTuple):
    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = 0

    @property
    def x_m(self) -> float:
        return self.x / LOCAL_SCALE

    @property
    def y_m(self) -> float:
        return self.y / LOCAL_SCALE

    def with_seq(self, seq: int) -> MissionItem:
        return self._replace(seq=seq)

    @property
    def xy_fit_int32(self) -> bool:
        return all(isinstance(v, int) and INT32_MIN <= v <= INT32_MAX for v in (self.x, self.y))


def local_xy(metres: float) -> int:
    """Metres to the int32 of MISSION_ITEM_INT in a local frame."""
    return round(metres * LOCAL_SCALE)


def xy_scale(frame: int) -> float:
    """MISSION_ITEM_INT's x, y per unit of the frame (degrees or metres)."""
    return GLOBAL_SCALE if frame in GLOBAL_FRAMES else LOCAL_SCALE


def _xy_int(value: float, scale: float) -> int:
    """A legacy float x or y as MISSION_ITEM_INT's integer; one that is not finite or does
    not fit int32 becomes INT32_MAX + 1, which validation refuses (INVALID_PARAM5_X / 6_Y)."""
    if math.isfinite(value) and abs(value * scale) <= INT32_MAX:
        return round(value * scale)
    return INT32_MAX + 1


def item_from_message(msg: Any) -> MissionItem:
    """A MISSION_ITEM_INT (x, y as sent) or a legacy MISSION_ITEM (x, y floats in the frame's
    unit, scaled by `xy_scale`) as a MissionItem."""
    x, y = msg.x, msg.y
    if msg.get_type() == "MISSION_ITEM":
        scale = xy_scale(msg.frame)
        x, y = _xy_int(x, scale), _xy_int(y, scale)
    return MissionItem(seq=msg.seq, frame=msg.frame, command=msg.command, current=msg.current,
                       autocontinue=msg.autocontinue, param1=msg.param1, param2=msg.param2,
                       param3=msg.param3, param4=msg.param4, x=x, y=y, z=msg.z,
                       mission_type=getattr(msg, "mission_type", MAV_MISSION_TYPE_MISSION))


def item_message(item: MissionItem, target_system: int, target_component: int,
                 current: int | None = None) -> Any:
    """The MISSION_ITEM_INT that carries `item` (`current` overrides the item's flag)."""
    from common.mavlink import MAV

    return MAV.MAVLink_mission_item_int_message(
        target_system, target_component, item.seq, item.frame, item.command,
        item.current if current is None else current, item.autocontinue, item.param1,
        item.param2, item.param3, item.param4, item.x, item.y, item.z, item.mission_type)
