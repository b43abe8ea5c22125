"""Mission validation: each item's parameters, the geofence, global frames through home, and
(with `MissionLimits.vehicle`) the actuator envelope of the planned segments.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from common.mission_items import (
    GEO_FRAMES,
    INT32_MAX,
    INT32_MIN,
    XY_COMMANDS,
    HomePosition,
    MissionItem,
    local_ned,
    to_local,
)
from fcu.dualquat import Q_IDENTITY, norm3
from fcu.mission.codes import (
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_LOITER_TIME,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MAV_CMD_POSE_KEYFRAME,
    MAV_FRAME_LOCAL_NED,
    MAV_MISSION_ACCEPTED,
    MAV_MISSION_DENIED,
    MAV_MISSION_INVALID_PARAM1,
    MAV_MISSION_INVALID_PARAM2,
    MAV_MISSION_INVALID_PARAM3,
    MAV_MISSION_INVALID_PARAM4,
    MAV_MISSION_INVALID_PARAM5_X,
    MAV_MISSION_INVALID_PARAM6_Y,
    MAV_MISSION_INVALID_PARAM7,
    MAV_MISSION_INVALID_SEQUENCE,
    MAV_MISSION_NO_SPACE,
    MAV_MISSION_UNSUPPORTED,
    MAV_MISSION_UNSUPPORTED_FRAME,
    SUPPORTED_COMMANDS,
)
from fcu.mission.limits import MissionLimits
from fcu.mission.planning import envelope_reason, plan_item
from fcu.mission.segments import ZERO

FIGURE_EXTENT = math.sqrt(5.0)  # max |[sin 2T, sin T, 1 - cos 2T]|
# MAVProxy's `wp load` scales local x, y by 1e7 instead of 1e4: 1 m in a file arrives as
# 1000 m. A local item this far out and beyond the geofence is refused with that hint.
SCALED_LOCAL_M = 1000.0


class MissionCheck(NamedTuple):
    """The outcome of validating a mission."""

    result: int  # MAV_MISSION_RESULT
    seq: int | None  # the offending item, if any
    reason: str = ""  # why, for a person: set for MAV_MISSION_DENIED, else ""


def _finite(x: float) -> bool:
    return math.isfinite(x)


def _time(x: float, positive: bool = False) -> bool:
    return math.isfinite(x) and (x > 0.0 if positive else x >= 0.0)


def _yaw(x: float) -> bool:
    """A yaw parameter: NaN (keep) or a finite angle."""
    return math.isnan(x) or math.isfinite(x)


def _outside(seq: int, reach_m: float, r: float) -> tuple[int, str]:
    return MAV_MISSION_DENIED, f"item {seq}: beyond the geofence ({reach_m:.0f} m > {r:.0f} m)"


def _scaled(item: MissionItem, r: float) -> tuple[int, str]:
    """A local item whose x, y lie beyond the geofence and at least SCALED_LOCAL_M away:
    most likely a local-frame WPL file loaded by MAVProxy, which scales x and y by 1e7 in
    every frame (1.5 m arrives as 15,000,000, read as 1500 m), where local frames take 1e4."""
    return MAV_MISSION_DENIED, (
        f"item {item.seq}: x {item.x_m:.0f} m, y {item.y_m:.0f} m, beyond the geofence "
        f"({r:.0f} m): a local WPL file scaled by 1e7 (MAVProxy)? use a global frame")


def _check_item(item: MissionItem, limits: MissionLimits, pos: list[float],
                geofence: bool = True) -> tuple[int, str]:
    """(MAV_MISSION_RESULT, reason) of one item's parameters and geofence; `pos` (planned NED
    position) moves to its end."""
    cmd = item.command
    if cmd not in SUPPORTED_COMMANDS:
        return MAV_MISSION_UNSUPPORTED, ""
    if item.frame != MAV_FRAME_LOCAL_NED:
        return MAV_MISSION_UNSUPPORTED_FRAME, ""
    # x, y must fit MISSION_ITEM_INT even where the command ignores them.
    if not (isinstance(item.x, int) and INT32_MIN <= item.x <= INT32_MAX):
        return MAV_MISSION_INVALID_PARAM5_X, ""
    if not (isinstance(item.y, int) and INT32_MIN <= item.y <= INT32_MAX):
        return MAV_MISSION_INVALID_PARAM6_Y, ""
    p1, p2, p3, p4, z = item.param1, item.param2, item.param3, item.param4, item.z
    r = limits.max_distance_m if geofence else math.inf
    if cmd == MAV_CMD_NAV_TAKEOFF:
        if not _time(p2):
            return MAV_MISSION_INVALID_PARAM2, ""
        if not _yaw(p4):
            return MAV_MISSION_INVALID_PARAM4, ""
        if not _finite(z):
            return MAV_MISSION_INVALID_PARAM7, ""
        target = [pos[0], pos[1], z]
    elif cmd in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TIME):
        if not _time(p1):
            return MAV_MISSION_INVALID_PARAM1, ""
        if cmd == MAV_CMD_NAV_WAYPOINT and not _yaw(p4):
            return MAV_MISSION_INVALID_PARAM4, ""
        if not _finite(z):
            return MAV_MISSION_INVALID_PARAM7, ""
        target = [item.x_m, item.y_m, z]
    elif cmd == MAV_CMD_NAV_LAND:
        if not _yaw(p4):
            return MAV_MISSION_INVALID_PARAM4, ""
        pos[2] = 0.0
        return MAV_MISSION_ACCEPTED, ""
    elif cmd == MAV_CMD_POSE_KEYFRAME:
        if not _time(p1, positive=True):
            return MAV_MISSION_INVALID_PARAM1, ""
        for value, code in ((p2, MAV_MISSION_INVALID_PARAM2), (p3, MAV_MISSION_INVALID_PARAM3),
                            (p4, MAV_MISSION_INVALID_PARAM4)):
            if not _finite(value):
                return code, ""
        if not _finite(z):
            return MAV_MISSION_INVALID_PARAM7, ""
        target = [item.x_m, item.y_m, z]
    else:  # MAV_CMD_FIGURE_EIGHT
        if not _time(p1):
            return MAV_MISSION_INVALID_PARAM1, ""
        if not _time(p2, positive=True):
            return MAV_MISSION_INVALID_PARAM2, ""
        if not _finite(p3):
            return MAV_MISSION_INVALID_PARAM3, ""
        if not _finite(p4):
            return MAV_MISSION_INVALID_PARAM4, ""
        if not _finite(z):
            return MAV_MISSION_INVALID_PARAM7, ""
        if p3 == 0.0 and p4 == 0.0 and z == 0.0:
            return MAV_MISSION_INVALID_PARAM3, ""  # no axis
        reach = norm3((pos[0], pos[1], pos[2])) + p1 * FIGURE_EXTENT
        if reach > r:
            return _outside(item.seq, reach, r)
        return MAV_MISSION_ACCEPTED, ""  # ends where it started (T = 2 pi)
    reach = norm3((target[0], target[1], target[2]))
    if reach > r:
        if item.command in XY_COMMANDS and \
                math.hypot(item.x_m, item.y_m) > max(r, SCALED_LOCAL_M):
            return _scaled(item, r)
        return _outside(item.seq, reach, r)
    pos[:] = target
    return MAV_MISSION_ACCEPTED, ""


def _localized(item: MissionItem, home: HomePosition | None,
               limits: MissionLimits) -> tuple[MissionItem, int, str]:
    """(the item in the local frame, MAV_MISSION_RESULT, reason): a GEO_FRAMES item with a
    supported command converted through `home` (none: MAV_MISSION_UNSUPPORTED_FRAME), its
    latitude and longitude checked first; any other item as it is."""
    if item.frame not in GEO_FRAMES or item.command not in SUPPORTED_COMMANDS:
        return item, MAV_MISSION_ACCEPTED, ""
    if home is None:
        return item, MAV_MISSION_UNSUPPORTED_FRAME, ""
    if not (isinstance(item.x, int) and -900_000_000 <= item.x <= 900_000_000):
        return item, MAV_MISSION_INVALID_PARAM5_X, ""
    if not (isinstance(item.y, int) and -1_800_000_000 <= item.y <= 1_800_000_000):
        return item, MAV_MISSION_INVALID_PARAM6_Y, ""
    local = to_local(item, home)
    if item.command in XY_COMMANDS and not local.xy_fit_int32:  # farther than 214 km
        north, east, _ = local_ned(item, home)
        result, reason = _outside(item.seq, math.hypot(north, east), limits.max_distance_m)
        return item, result, reason
    return local, MAV_MISSION_ACCEPTED, ""


def localize(items: Sequence[MissionItem],
             home: HomePosition | None) -> tuple[MissionItem, ...]:
    """The items as the executor flies them: global-frame items converted to the local frame
    through `home` (`common.mission_items.to_local`); for a mission `check_mission` accepted
    with the same home."""
    if home is None:
        return tuple(items)
    return tuple(to_local(it, home) if it.command in SUPPORTED_COMMANDS else it
                 for it in items)


def check_mission(items: Sequence[MissionItem], limits: MissionLimits,
                  home: HomePosition | None = None) -> MissionCheck:
    """Validate a whole mission: (MAV_MISSION_RESULT, offending seq or None, reason).

    Items in MAV_FRAME_LOCAL_NED, or, with `home`, in a global frame with an altitude
    (common.mission_items.GEO_FRAMES: AMSL or above home, INT or not), checked as their
    local equivalents (`localize`); other frames are MAV_MISSION_UNSUPPORTED_FRAME. A local
    item whose x, y lie beyond the geofence and SCALED_LOCAL_M or more away is refused with a
    reason naming MAVProxy's 1e7 scaling of local WPL files (its likeliest cause).

    Seqs must be 0..n-1 in order. Only the parameters an item uses are checked. The
    geofence check follows the planned positions from the origin (the mission's start):
    takeoff keeps x, y, landing goes to z = 0, the figure returns to its start. With
    `limits.vehicle`, the mission is also planned from the origin at the identity attitude,
    speed-timed items stretched, and an item whose given duration the vehicle cannot fly is
    MAV_MISSION_DENIED with a reason such as "item 3: tilt servo 2 needs 13.1 rad/s, limit 2.0
    (50% of 4.0): lengthen p1 to 2.31 s" (the `fcu.mission` docstring). Items are checked in
    order: the first failing item is reported.
    """
    if len(items) > limits.max_items:
        return MissionCheck(MAV_MISSION_NO_SPACE, None)
    return check_items(items, limits, geofence=True, envelope_check=limits.vehicle is not None,
                        home=home)


def validate_mission(items: Sequence[MissionItem], limits: MissionLimits,
                     home: HomePosition | None = None) -> tuple[int, int | None]:
    """(MAV_MISSION_RESULT, offending seq or None) of `check_mission`."""
    check = check_mission(items, limits, home)
    return check.result, check.seq


def check_items(items: Sequence[MissionItem], limits: MissionLimits, geofence: bool,
                 envelope_check: bool = False,
                 home: HomePosition | None = None) -> MissionCheck:
    pos = [0.0, 0.0, 0.0]
    t, p, q = 0.0, ZERO, Q_IDENTITY
    for i, item in enumerate(items):
        if item.seq != i:
            return MissionCheck(MAV_MISSION_INVALID_SEQUENCE, item.seq)
        item, result, reason = _localized(item, home, limits)
        if result != MAV_MISSION_ACCEPTED:
            return MissionCheck(result, item.seq, reason)
        result, reason = _check_item(item, limits, pos, geofence)
        if result != MAV_MISSION_ACCEPTED:
            return MissionCheck(result, item.seq, reason)
        if envelope_check:
            seg = plan_item(item, t, p, q, limits)
            reason = envelope_reason(item, seg, limits)
            if reason:
                return MissionCheck(MAV_MISSION_DENIED, item.seq, reason)
            t, p, q = seg.t1, seg.p_end, seg.q_end
    return MissionCheck(MAV_MISSION_ACCEPTED, None)

