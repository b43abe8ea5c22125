"""Mission items as MISSION_ITEM_INT carries them (local frames: x, y in 1e-4 m), and the one
conversion between items and MAVLink mission messages (vehicle and ground station alike).

x and y of MISSION_ITEM_INT are int32: metres x 1e4 in local frames, degrees x 1e7 in global
ones (MAVLink's common.xml); the legacy MISSION_ITEM carries them as floats in metres or
degrees. The message an item travels in is built at the edge
(`common.wire.mission_messages.item_message`): this module loads no MAVLink library, so the
flight code can use `MissionItem` without one.

Global frames and the local one meet at the home position (`HomePosition`, as HOME_POSITION
publishes it): `to_local` and `to_global` convert the items whose slots hold a position
(`common.geodetic.geodetic_to_ned` / `ned_to_geodetic`, one tangent plane), so the vehicle and
the ground station convert alike.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from common.geodetic import geodetic_to_ned, ned_to_geodetic
from common.wire.mav_enums import MAV_CMD, MAV_FRAME, MAV_MISSION_TYPE
from common.wire.mavlink_types import as_message
from common.wire.mavlink_types.protocol import MissionItem as LegacyMissionItem
from common.wire.mavlink_types.protocol import MissionItemInt
from common.wire.mavlink_types.state import HomePosition as HomePositionMessage

LOCAL_SCALE = 1e4  # MISSION_ITEM_INT x, y in local frames: metres x 1e4
GLOBAL_SCALE = 1e7  # MISSION_ITEM_INT x, y in global frames: degrees x 1e7
INT32_MIN, INT32_MAX = -(2 ** 31), 2 ** 31 - 1
# The global frames: x, y in 1e-7 deg.
GLOBAL_FRAMES: frozenset[int] = frozenset({
    MAV_FRAME.MAV_FRAME_GLOBAL, MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    MAV_FRAME.MAV_FRAME_GLOBAL_INT, MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    MAV_FRAME.MAV_FRAME_GLOBAL_TERRAIN_ALT, MAV_FRAME.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT})
# imported by gcs.vehicle_link.mission_home:
MAV_FRAME_GLOBAL: int = MAV_FRAME.MAV_FRAME_GLOBAL
MAV_FRAME_LOCAL_NED: int = MAV_FRAME.MAV_FRAME_LOCAL_NED
# Global frames that a home position converts: altitude AMSL, altitude above home (the
# non-INT ones as MAVProxy sends them in MISSION_ITEM_INT, x and y in 1e-7 deg all the same).
# The terrain frames are not among them: the vehicle knows no terrain.
AMSL_FRAMES: frozenset[int] = frozenset({MAV_FRAME.MAV_FRAME_GLOBAL,
                                         MAV_FRAME.MAV_FRAME_GLOBAL_INT})
RELATIVE_ALT_FRAMES: frozenset[int] = frozenset({MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                                                 MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
GEO_FRAMES: frozenset[int] = AMSL_FRAMES | RELATIVE_ALT_FRAMES
# The deprecated _INT global frames and the frame each means: MISSION_ITEM_INT carries
# degE7 in either. Neither firmware keeps the difference: PX4 stores only whether the
# altitude is relative and answers MISSION_REQUEST_INT in the _INT frames (its
# mavlink_mission.cpp), ArduPilot answers in the plain ones (AP_Mission). A download reads
# them as the plain frames, so that a file's 3 comes back 3 from either.
PLAIN_FRAMES: dict[int, int] = {
    MAV_FRAME.MAV_FRAME_GLOBAL_INT: MAV_FRAME.MAV_FRAME_GLOBAL,
    MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    MAV_FRAME.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: MAV_FRAME.MAV_FRAME_GLOBAL_TERRAIN_ALT}
# The commands of fcu.mission and what their x, y, z hold (docs/missions.md#items-and-commands):
# NAV_WAYPOINT, NAV_LOITER_TIME and the pose keyframe (WAYPOINT_USER_1) fly to x, y, z;
# NAV_TAKEOFF climbs to z and NAV_LAND ignores it (an altitude all the same); the
# figure-infinity's (WAYPOINT_USER_2) z is an axis component. x, y of takeoff, land and the
# figure are unused.
XY_COMMANDS: frozenset[int] = frozenset({MAV_CMD.MAV_CMD_NAV_WAYPOINT,
                                         MAV_CMD.MAV_CMD_NAV_LOITER_TIME,
                                         MAV_CMD.MAV_CMD_WAYPOINT_USER_1})
Z_ALTITUDE_COMMANDS: frozenset[int] = XY_COMMANDS | {MAV_CMD.MAV_CMD_NAV_LAND,
                                                     MAV_CMD.MAV_CMD_NAV_TAKEOFF}
POSITION_COMMANDS: frozenset[int] = Z_ALTITUDE_COMMANDS | {MAV_CMD.MAV_CMD_WAYPOINT_USER_2}


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


def item_from_message(msg: MissionItemInt | LegacyMissionItem) -> MissionItem:
    """A MISSION_ITEM_INT (x, y as sent) or a legacy MISSION_ITEM (x, y floats in the frame's
    unit, scaled by `xy_scale`) as a MissionItem."""
    if msg.get_type() == "MISSION_ITEM":
        legacy = as_message(msg, LegacyMissionItem)
        scale = xy_scale(legacy.frame)
        x, y = _xy_int(legacy.x, scale), _xy_int(legacy.y, scale)
    else:
        item_int = as_message(msg, MissionItemInt)
        x, y = item_int.x, item_int.y
    return MissionItem(seq=msg.seq, frame=msg.frame, command=msg.command, current=msg.current,
                       autocontinue=msg.autocontinue, param1=msg.param1, param2=msg.param2,
                       param3=msg.param3, param4=msg.param4, x=x, y=y, z=msg.z,
                       mission_type=getattr(msg, "mission_type",
                                            MAV_MISSION_TYPE.MAV_MISSION_TYPE_MISSION))


# ------------------------------------------------------------------ frames


class HomePosition(NamedTuple):
    """The origin of the local frame: latitude, longitude (deg) and altitude AMSL (m)."""

    lat_deg: float
    lon_deg: float
    alt_m: float

    @classmethod
    def published(cls, lat_deg: float, lon_deg: float, alt_m: float) -> HomePosition:
        """The home as HOME_POSITION carries it (1e-7 deg, mm): what ground stations see, so
        that the vehicle converts global items through the same numbers they do."""
        return cls(round(lat_deg * GLOBAL_SCALE) / GLOBAL_SCALE,
                   round(lon_deg * GLOBAL_SCALE) / GLOBAL_SCALE, round(alt_m * 1000.0) / 1000.0)

    @classmethod
    def from_message(cls, msg: HomePositionMessage) -> HomePosition:
        """From a HOME_POSITION message."""
        return cls(msg.latitude / GLOBAL_SCALE, msg.longitude / GLOBAL_SCALE,
                   msg.altitude / 1000.0)


# PX4's SITL default home (its Gazebo worlds and jMAVSim: a field near Zurich), where the
# shipped sensor profiles' earth field (WMM, about 47 N 8 E) holds: the FCU's and the
# simulator's default origin.
PX4_SITL_HOME = HomePosition(47.397742, 8.545594, 488.0)


def local_ned(item: MissionItem, home: HomePosition) -> tuple[float, float, float]:
    """(north, east, down) in metres of a GEO_FRAMES item's x, y, z relative to `home`
    (down = -z above home in the relative-altitude frames, home alt - z in AMSL ones)."""
    base_alt = 0.0 if item.frame in RELATIVE_ALT_FRAMES else home.alt_m
    return geodetic_to_ned(item.x / GLOBAL_SCALE, item.y / GLOBAL_SCALE, item.z, home.lat_deg,
                           home.lon_deg, base_alt)


def to_local(item: MissionItem, home: HomePosition) -> MissionItem:
    """`item` in MAV_FRAME_LOCAL_NED when it is in one of GEO_FRAMES with a command of
    POSITION_COMMANDS, else unchanged. x, y unused by the command become 0; a position too
    far from home for MISSION_ITEM_INT's local int32 (214 km) keeps an x or y outside it,
    which validation refuses."""
    if item.frame not in GEO_FRAMES or item.command not in POSITION_COMMANDS:
        return item
    north, east, down = local_ned(item, home)
    x = y = 0
    if item.command in XY_COMMANDS:
        x, y = _local_int(north), _local_int(east)
    z = down if item.command in Z_ALTITUDE_COMMANDS else item.z
    return item._replace(frame=MAV_FRAME.MAV_FRAME_LOCAL_NED, x=x, y=y, z=z)


def _local_int(metres: float) -> int:
    return round(metres * LOCAL_SCALE) if math.isfinite(metres) and \
        abs(metres * LOCAL_SCALE) <= INT32_MAX else INT32_MAX + 1


def to_global(item: MissionItem, home: HomePosition,
              frame: int = MAV_FRAME.MAV_FRAME_GLOBAL_RELATIVE_ALT) -> MissionItem:
    """`item` in `frame` (one of GEO_FRAMES) when it is a MAV_FRAME_LOCAL_NED item with a
    command of POSITION_COMMANDS, else unchanged: x, y the latitude and longitude of its
    north, east (1e-7 deg, rounded), z the altitude above home or AMSL (the figure's z, an
    axis component, stays). Unused x, y convert as positions too (the origin for 0, 0), so
    a reader sees the item where it starts."""
    if frame not in GEO_FRAMES:
        raise ValueError(f"frame {frame} is not a global frame with an altitude")
    if item.frame != MAV_FRAME.MAV_FRAME_LOCAL_NED or item.command not in POSITION_COMMANDS:
        return item
    base_alt = 0.0 if frame in RELATIVE_ALT_FRAMES else home.alt_m
    lat, lon, alt = ned_to_geodetic((item.x_m, item.y_m, item.z), home.lat_deg,
                                    home.lon_deg, base_alt)
    z = alt if item.command in Z_ALTITUDE_COMMANDS else item.z
    return item._replace(frame=frame, x=round(lat * GLOBAL_SCALE),
                         y=round(lon * GLOBAL_SCALE), z=z)


def plain_frame(item: MissionItem) -> MissionItem:
    """`item` in the plain global frame where it is in a deprecated _INT one (PLAIN_FRAMES;
    the same numbers: MISSION_ITEM_INT's x, y are degE7 in both)."""
    frame = PLAIN_FRAMES.get(item.frame)
    return item if frame is None else item._replace(frame=frame)
