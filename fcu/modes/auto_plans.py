"""The automatic modes' plans as missions (NAV_TAKEOFF, NAV_WAYPOINT, NAV_LAND items in
MAV_FRAME_LOCAL_NED) for the mission executor to fly; pure, no I/O.

TAKEOFF climbs straight up from where the vehicle should be; RTL climbs to its return
altitude above home if it is lower, flies to home's north and east and lands there; LAND
descends vertically from where it starts. Home is the origin of the local frame.
"""

from __future__ import annotations

import math

from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mission_items import MissionItem
from fcu.control.dualquat import Vec3, norm3

_LOCAL_NED = MAV_FRAME.MAV_FRAME_LOCAL_NED


def _item(seq: int, command: int, z_ned_m: float) -> MissionItem:
    """An item at home's north and east (x = y = 0) and `z_ned_m`, the first one current."""
    return MissionItem(seq, _LOCAL_NED, command, int(seq == 0), 1, 0.0, 0.0, 0.0, math.nan,
                       0, 0, z_ned_m)


def takeoff(p_enu_m: Vec3, climb_m: float, max_distance_m: float
            ) -> tuple[MissionItem, ...] | str:
    """TAKEOFF's climb by `climb_m` from `p_enu_m` (one NAV_TAKEOFF item), or why it is
    refused."""
    return takeoff_to(p_enu_m, -(p_enu_m[2] + climb_m), max_distance_m)


def takeoff_to(p_enu_m: Vec3, z_ned: float, max_distance_m: float
               ) -> tuple[MissionItem, ...] | str:
    """TAKEOFF's climb from `p_enu_m` straight up to `z_ned` (one NAV_TAKEOFF item), or why
    it is refused: its target beyond GF_MAX_DIST."""
    if norm3((p_enu_m[1], p_enu_m[0], z_ned)) > max_distance_m:
        return "takeoff: beyond GF_MAX_DIST"
    return (_item(0, MAV_CMD.MAV_CMD_NAV_TAKEOFF, z_ned),)


def rtl(p_enu_m: Vec3, return_alt_m: float, max_distance_m: float
        ) -> tuple[MissionItem, ...] | str:
    """RTL from `p_enu_m`: climb to `return_alt_m` above home if lower, travel home, land;
    or why it is refused."""
    z_ned = min(-p_enu_m[2], -return_alt_m)
    if abs(z_ned) > max_distance_m:
        return "RTL: return altitude beyond GF_MAX_DIST"
    return (_item(0, MAV_CMD.MAV_CMD_NAV_TAKEOFF, z_ned),
            _item(1, MAV_CMD.MAV_CMD_NAV_WAYPOINT, z_ned),
            _item(2, MAV_CMD.MAV_CMD_NAV_LAND, 0.0))


def land() -> tuple[MissionItem, ...]:
    """LAND: NAV_LAND descends vertically from where it starts (x, y are not used)."""
    return (_item(0, MAV_CMD.MAV_CMD_NAV_LAND, 0.0),)
