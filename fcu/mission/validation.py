"""Mission validation: each item's parameters, the geofence, global frames through home, and
(with `MissionLimits.vehicle`) the actuator envelope of the planned segments.

Every refusal has a reason for a person, naming the item (its seq) and what is wrong with
it, or for MAV_MISSION_NO_SPACE the count and the limit; `refusal` puts the
MAV_MISSION_RESULT's name in front ("MAV_MISSION_UNSUPPORTED: item 2: command 177 is not
supported").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

from common.wire.mav_enums import MAV_CMD, MAV_FRAME
from common.wire.mav_enums import MAV_MISSION_RESULT as MISSION_RESULT
from common.wire.mission_items import (
    GEO_FRAMES,
    INT32_MAX,
    INT32_MIN,
    XY_COMMANDS,
    HomePosition,
    MissionItem,
    local_ned,
    to_local,
)
from fcu.control.dualquat import Q_IDENTITY, norm3
from fcu.mission.codes import (
    FRAMELESS_COMMANDS,
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_FIGURE_EIGHT,
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
    result_name,
)
from fcu.mission.limits import MissionLimits
from fcu.mission.planning import (
    SPEED_DEFAULT,
    SPEED_FIELDS,
    SPEED_NO_CHANGE,
    plan_item,
    with_speed,
)
from fcu.mission.segments import ZERO
from fcu.mission.verdicts import Planned, first_refusal

FIGURE_EXTENT = math.sqrt(5.0)  # max |[sin 2T, sin T, 1 - cos 2T]|
# MAVProxy's `wp load` scales local x, y by 1e7 instead of 1e4: 1 m in a file arrives as
# 1000 m. A local item this far out and beyond the geofence is refused with that hint.
SCALED_LOCAL_M = 1000.0


class Verdict(NamedTuple):
    """One check of an item: its MAV_MISSION_RESULT and why, for a person ("" if accepted)."""

    result: MISSION_RESULT
    reason: str = ""


ACCEPTED = Verdict(MAV_MISSION_ACCEPTED)


class MissionCheck(NamedTuple):
    """The outcome of validating a mission."""

    result: MISSION_RESULT
    seq: int | None  # the offending item, if any
    reason: str = ""  # why, for a person: set for every refusal, "" when accepted


def refusal(check: MissionCheck) -> str:
    """A refusal for a person: the MAV_MISSION_RESULT by name, then the reason, e.g.
    "MAV_MISSION_NO_SPACE: 501 items: the vehicle holds at most 500"; "" when accepted."""
    if check.result == MAV_MISSION_ACCEPTED:
        return ""
    return f"{result_name(check.result)}: {check.reason}" if check.reason else \
        result_name(check.result)


def _finite(x: float) -> bool:
    """A finite number."""
    return math.isfinite(x)


def _time_s(x: float) -> bool:
    """A duration: finite and >= 0."""
    return math.isfinite(x) and x >= 0.0


def _positive_time_s(x: float) -> bool:
    """A duration that must pass: finite and > 0."""
    return math.isfinite(x) and x > 0.0


def _yaw(x: float) -> bool:
    """A yaw parameter: NaN (keep) or a finite angle."""
    return math.isnan(x) or math.isfinite(x)


def _speed_type(x: float) -> bool:
    """DO_CHANGE_SPEED's p1: a SPEED_TYPE (0 air, 1 ground, 2 climb, 3 descent speed)."""
    return x in SPEED_FIELDS


def _speed(x: float) -> bool:
    """DO_CHANGE_SPEED's p2: a speed > 0 m/s, -1 (no change) or -2 (the default)."""
    return (math.isfinite(x) and x > 0.0) or x in (SPEED_NO_CHANGE, SPEED_DEFAULT)


def _int32(v: int) -> bool:
    """An x or y that fits MISSION_ITEM_INT's int32."""
    return isinstance(v, int) and INT32_MIN <= v <= INT32_MAX


# What each rule asks of a value, for the reasons.
_RULE_TEXT: dict[Callable[[float], bool], str] = {
    _finite: "a finite number", _time_s: "a duration >= 0 s",
    _positive_time_s: "a duration > 0 s", _yaw: "an angle in deg, or NaN to keep it",
    _speed_type: "a speed type: 0 air, 1 ground, 2 climb or 3 descent speed",
    _speed: "a speed > 0 m/s, -1 (no change) or -2 (the default)"}
# How the reasons name the fields.
_FIELD_TEXT = {"param1": "p1", "param2": "p2", "param3": "p3", "param4": "p4", "z": "z"}


def _name(enum: type[MAV_CMD] | type[MAV_FRAME], value: int) -> str:
    """`value` with its name where `common.wire.mav_enums` knows it:
    "178 (MAV_CMD_DO_CHANGE_SPEED)"."""
    try:
        return f"{value} ({enum(value).name})"
    except ValueError:
        return str(value)


# The parameters each command uses, in the order they are checked (the first failing one is
# the result): (MissionItem field, its rule, the refusal).
_PARAM_RULES: dict[int, tuple[tuple[str, Callable[[float], bool], MISSION_RESULT], ...]] = {
    MAV_CMD_NAV_TAKEOFF: (("param2", _time_s, MAV_MISSION_INVALID_PARAM2),
                          ("param4", _yaw, MAV_MISSION_INVALID_PARAM4),
                          ("z", _finite, MAV_MISSION_INVALID_PARAM7)),
    MAV_CMD_NAV_WAYPOINT: (("param1", _time_s, MAV_MISSION_INVALID_PARAM1),
                           ("param4", _yaw, MAV_MISSION_INVALID_PARAM4),
                           ("z", _finite, MAV_MISSION_INVALID_PARAM7)),
    MAV_CMD_NAV_LOITER_TIME: (("param1", _time_s, MAV_MISSION_INVALID_PARAM1),
                              ("z", _finite, MAV_MISSION_INVALID_PARAM7)),
    MAV_CMD_NAV_LAND: (("param4", _yaw, MAV_MISSION_INVALID_PARAM4),),
    MAV_CMD_POSE_KEYFRAME: (("param1", _positive_time_s, MAV_MISSION_INVALID_PARAM1),
                            ("param2", _finite, MAV_MISSION_INVALID_PARAM2),
                            ("param3", _finite, MAV_MISSION_INVALID_PARAM3),
                            ("param4", _finite, MAV_MISSION_INVALID_PARAM4),
                            ("z", _finite, MAV_MISSION_INVALID_PARAM7)),
    MAV_CMD_DO_CHANGE_SPEED: (("param1", _speed_type, MAV_MISSION_INVALID_PARAM1),
                              ("param2", _speed, MAV_MISSION_INVALID_PARAM2)),
    MAV_CMD_FIGURE_EIGHT: (("param1", _time_s, MAV_MISSION_INVALID_PARAM1),
                           ("param2", _positive_time_s, MAV_MISSION_INVALID_PARAM2),
                           ("param3", _finite, MAV_MISSION_INVALID_PARAM3),
                           ("param4", _finite, MAV_MISSION_INVALID_PARAM4),
                           ("z", _finite, MAV_MISSION_INVALID_PARAM7)),
}


def compared(above: float, below: float) -> tuple[str, str]:
    """`above` and `below` (above > below, e.g. a distance and the geofence) as texts:
    `below` as it was set (6 significant digits: a float32 parameter's), `above` with as few
    decimals, no fewer than `below`'s, as make the comparison true as printed (1000.0004 and
    1000 as "1000.0004", "1000"; 50 and 30 as "50", "30")."""
    fence = f"{below:.6g}"
    if "e" in fence:
        return repr(above), repr(below)
    start = len(fence.split(".")[1]) if "." in fence else 0
    for decimals in range(start, 10):
        a = f"{above:.{decimals}f}"
        if float(a) > float(fence):
            return a, fence
    return repr(above), repr(below)


def _outside(seq: int, reach_m: float, r: float) -> Verdict:
    """MAV_MISSION_DENIED for an item reaching `reach_m` from the origin, beyond radius r:
    the distance that went beyond it, precise enough that the comparison reads true."""
    reach, fence = compared(reach_m, r)
    return Verdict(MAV_MISSION_DENIED,
                   f"item {seq}: beyond the geofence ({reach} m > {fence} m)")


def _scaled(item: MissionItem, r: float) -> Verdict:
    """A local item whose x, y lie beyond the geofence and at least SCALED_LOCAL_M away:
    most likely a local-frame WPL file loaded by MAVProxy, which scales x and y by 1e7 in
    every frame (1.5 m arrives as 15,000,000, read as 1500 m), where local frames take 1e4."""
    return Verdict(MAV_MISSION_DENIED, (
        f"item {item.seq}: x {item.x_m:.0f} m, y {item.y_m:.0f} m, beyond the geofence "
        f"({r:.0f} m): a local WPL file scaled by 1e7 (MAVProxy)? use a global frame"))


def _carried_result(item: MissionItem) -> Verdict:
    """The verdict on the command, the frame and x, y (which must fit
    MISSION_ITEM_INT even where the command ignores them)."""
    if item.command not in SUPPORTED_COMMANDS:
        return Verdict(MAV_MISSION_UNSUPPORTED, (
            f"item {item.seq}: command {_name(MAV_CMD, item.command)} is not supported"))
    if item.frame != MAV_FRAME_LOCAL_NED and item.command not in FRAMELESS_COMMANDS:
        return Verdict(MAV_MISSION_UNSUPPORTED_FRAME, (
            f"item {item.seq}: frame {_name(MAV_FRAME, item.frame)} is not supported (local "
            "NED, or global with an altitude)"))
    if _int32(item.x) and _int32(item.y):
        return ACCEPTED
    for field, v, result in (("x", item.x, MAV_MISSION_INVALID_PARAM5_X),
                             ("y", item.y, MAV_MISSION_INVALID_PARAM6_Y)):
        if not _int32(v):
            return Verdict(result, f"item {item.seq}: {field} {v} does not fit "
                                   "MISSION_ITEM_INT's int32")
    return ACCEPTED


def _params_result(item: MissionItem) -> Verdict:
    """The verdict on the parameters the item's command uses
    (`_PARAM_RULES`)."""
    for field, rule, result in _PARAM_RULES[item.command]:
        value: float = getattr(item, field)
        if not rule(value):
            return Verdict(result, (f"item {item.seq}: {_FIELD_TEXT[field]} {value:g}: "
                                    f"must be {_RULE_TEXT[rule]}"))
    return ACCEPTED


def _fly_to(item: MissionItem, target_ned_m: list[float], pos: list[float],
            r: float) -> Verdict:
    """An item ending at `target_ned_m`: inside the geofence radius r, `pos` moves there
    (no geofence, r = inf: always)."""
    if r == math.inf:
        pos[:] = target_ned_m
        return ACCEPTED
    x, y, z = target_ned_m
    if isinstance(x, float) and isinstance(y, float) and isinstance(z, float):
        reach = math.sqrt(x * x + y * y + z * z)  # `norm3`'s operations, without its call
    else:
        reach = norm3((x, y, z))
    if reach > r:
        if item.command in XY_COMMANDS and \
                math.hypot(item.x_m, item.y_m) > max(r, SCALED_LOCAL_M):
            return _scaled(item, r)
        return _outside(item.seq, reach, r)
    pos[:] = target_ned_m
    return ACCEPTED


def _take_off(item: MissionItem, pos: list[float], r: float) -> Verdict:
    """NAV_TAKEOFF: climbs to z over the planned x, y."""
    return _fly_to(item, [pos[0], pos[1], item.z], pos, r)


def _go_to(item: MissionItem, pos: list[float], r: float) -> Verdict:
    """NAV_WAYPOINT, NAV_LOITER_TIME and the pose keyframe: fly to x, y, z."""
    return _fly_to(item, [item.x_m, item.y_m, item.z], pos, r)


def _land(item: MissionItem, pos: list[float], r: float) -> Verdict:
    """NAV_LAND: down to z = 0 where it is (always inside the geofence)."""
    pos[2] = 0.0
    return ACCEPTED


def _stay(item: MissionItem, pos: list[float], r: float) -> Verdict:
    """An item without motion (DO_CHANGE_SPEED)."""
    return ACCEPTED


def _figure_eight(item: MissionItem, pos: list[float], r: float) -> Verdict:
    """The figure-infinity: an axis (p3, p4, z) not zero, its reach (amplitude p1 times
    FIGURE_EXTENT from the start) inside the geofence; it ends where it started (T = 2 pi)."""
    if item.param3 == 0.0 and item.param4 == 0.0 and item.z == 0.0:
        return Verdict(MAV_MISSION_INVALID_PARAM3,
                       f"item {item.seq}: the figure's axis (p3, p4, z) is zero")
    reach = norm3((pos[0], pos[1], pos[2])) + item.param1 * FIGURE_EXTENT
    if reach > r:
        return _outside(item.seq, reach, r)
    return ACCEPTED


# Where each command's item goes, with its geofence check: (item, pos, radius r) -> result.
_MOTIONS: dict[int, Callable[[MissionItem, list[float], float], Verdict]] = {
    MAV_CMD_NAV_TAKEOFF: _take_off,
    MAV_CMD_NAV_WAYPOINT: _go_to,
    MAV_CMD_NAV_LOITER_TIME: _go_to,
    MAV_CMD_POSE_KEYFRAME: _go_to,
    MAV_CMD_NAV_LAND: _land,
    MAV_CMD_FIGURE_EIGHT: _figure_eight,
    MAV_CMD_DO_CHANGE_SPEED: _stay,
}


def _check_item(item: MissionItem, limits: MissionLimits, pos: list[float],
                geofence: bool = True) -> Verdict:
    """The verdict on one item's parameters and geofence; `pos` (planned NED position) moves
    to its end."""
    verdict = _carried_result(item)
    if verdict.result == MAV_MISSION_ACCEPTED:
        verdict = _params_result(item)
    if verdict.result != MAV_MISSION_ACCEPTED:
        return verdict
    r = limits.max_distance_m if geofence else math.inf
    return _MOTIONS[item.command](item, pos, r)


def _localized(item: MissionItem, home: HomePosition | None,
               limits: MissionLimits) -> tuple[MissionItem, Verdict]:
    """(the item in the local frame, the verdict): a GEO_FRAMES item with a
    supported command converted through `home` (none: MAV_MISSION_UNSUPPORTED_FRAME), its
    latitude and longitude checked first; any other item as it is."""
    if item.frame not in GEO_FRAMES or item.command not in SUPPORTED_COMMANDS or \
            item.command in FRAMELESS_COMMANDS:
        return item, ACCEPTED
    if home is None:
        return item, Verdict(MAV_MISSION_UNSUPPORTED_FRAME, (
            f"item {item.seq}: frame {_name(MAV_FRAME, item.frame)} needs the vehicle's home"))
    if not (isinstance(item.x, int) and -900_000_000 <= item.x <= 900_000_000):
        return item, Verdict(MAV_MISSION_INVALID_PARAM5_X,
                             f"item {item.seq}: latitude {item.x} (1e-7 deg) beyond +-90 deg")
    if not (isinstance(item.y, int) and -1_800_000_000 <= item.y <= 1_800_000_000):
        return item, Verdict(MAV_MISSION_INVALID_PARAM6_Y,
                             f"item {item.seq}: longitude {item.y} (1e-7 deg) beyond +-180 deg")
    local = to_local(item, home)
    if item.command in XY_COMMANDS and not local.xy_fit_int32:  # farther than 214 km
        north, east, _ = local_ned(item, home)
        return item, _outside(item.seq, math.hypot(north, east), limits.max_distance_m)
    return local, ACCEPTED


def localize(items: Sequence[MissionItem],
             home: HomePosition | None) -> tuple[MissionItem, ...]:
    """The items as the executor flies them: global-frame items converted to the local frame
    through `home` (`common.wire.mission_items.to_local`); for a mission `check_mission` accepted
    with the same home."""
    if home is None:
        return tuple(items)
    return tuple(to_local(it, home) if it.command in SUPPORTED_COMMANDS else it
                 for it in items)


def check_mission(items: Sequence[MissionItem], limits: MissionLimits,
                  home: HomePosition | None = None) -> MissionCheck:
    """Validate a whole mission: (MAV_MISSION_RESULT, offending seq or None, reason).

    Items in MAV_FRAME_LOCAL_NED, or, with `home`, in a global frame with an altitude
    (common.wire.mission_items.GEO_FRAMES: AMSL or above home, INT or not), checked as their
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
        return MissionCheck(MAV_MISSION_NO_SPACE, None, too_many(len(items), limits))
    return check_items(items, limits, geofence=True, envelope_check=limits.vehicle is not None,
                        home=home)


def too_many(count: int, limits: MissionLimits) -> str:
    """The reason of MAV_MISSION_NO_SPACE: the count and the limit."""
    return f"{count} items: the vehicle holds at most {limits.max_items}"


def validate_mission(items: Sequence[MissionItem], limits: MissionLimits,
                     home: HomePosition | None = None) -> tuple[MISSION_RESULT, int | None]:
    """(MAV_MISSION_RESULT, offending seq or None) of `check_mission`."""
    check = check_mission(items, limits, home)
    return check.result, check.seq


def check_items(items: Sequence[MissionItem], limits: MissionLimits, geofence: bool,
                 envelope_check: bool = False,
                 home: HomePosition | None = None) -> MissionCheck:
    """`check_mission` without the item count, the geofence optional. The envelope is
    judged once every item before the first refused one is planned (`first_refusal`: the
    plan from the origin does not depend on it), the first item it refuses reported before
    any later refusal."""
    pos = [0.0, 0.0, 0.0]
    t, p, q = 0.0, ZERO, Q_IDENTITY
    planned = limits  # with the speeds of the DO_CHANGE_SPEED items so far
    plan: list[Planned] = []
    refused = MissionCheck(MAV_MISSION_ACCEPTED, None)
    failed: Exception | None = None
    for i, item in enumerate(items):
        if item.seq != i:
            refused = MissionCheck(MAV_MISSION_INVALID_SEQUENCE, item.seq,
                                   f"item {item.seq} sent as item {i} (seq must be 0..n-1 "
                                   "in order)")
            break
        item, verdict = _localized(item, home, limits)
        if verdict.result == MAV_MISSION_ACCEPTED:
            verdict = _check_item(item, limits, pos, geofence)
        if verdict.result != MAV_MISSION_ACCEPTED:
            refused = MissionCheck(verdict.result, item.seq, verdict.reason)
            break
        planned = with_speed(item, planned, limits)
        if envelope_check:
            try:
                seg = plan_item(item, t, p, q, planned, stretch=False, scaled=False)
            except Exception as e:  # raised once the items before it pass
                failed = e
                break
            plan.append((item, seg, planned))
            t, p, q = seg.t1, seg.p_end, seg.q_end
    k, reason = first_refusal(plan)
    if reason:
        return MissionCheck(MAV_MISSION_DENIED, plan[k][0].seq, reason)
    if failed is not None:
        raise failed
    return refused
