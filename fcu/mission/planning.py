"""Planning one item: its segment from the start pose and time, stretched to what the vehicle can
fly (speed-timed items), and why a user-timed item cannot be flown (`fcu.envelope.feasibility`).
"""

from __future__ import annotations

import math
from dataclasses import replace

from common.config.scenario import VehicleConfig
from common.frames import ned_to_enu, q_ned_frd_to_enu_flu
from common.wire.mission_items import MissionItem
from fcu.control.dualquat import Quat, Vec3, norm3, q_conj, q_exp, q_log, q_mul
from fcu.envelope.feasibility import envelope
from fcu.mission.codes import (
    MAV_CMD_DO_CHANGE_SPEED,
    MAV_CMD_FIGURE_EIGHT,
    MAV_CMD_NAV_LAND,
    MAV_CMD_NAV_LOITER_TIME,
    MAV_CMD_NAV_TAKEOFF,
    MAV_CMD_NAV_WAYPOINT,
    MAV_CMD_POSE_KEYFRAME,
)
from fcu.mission.limits import MissionLimits
from fcu.mission.segments import (
    ZERO,
    Figure,
    Move,
    Segment,
    _floats,
    keyframe_turn,
    level_attitude,
)
from fcu.reference.trajectory import QUINTIC_PEAK_RATE

POSITION_TOLERANCE_M = 1e-3  # well above the wire's resolution (1e-4 m for x, y; float32 z)
ANGLE_TOLERANCE_RAD = 1e-4


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _turn(q0: Quat, yaw_deg: float) -> Vec3 | None:
    """Rotation vector from q0 to the level attitude at yaw_deg (None: keep the attitude)."""
    if math.isnan(yaw_deg):
        return None
    phi = q_log(q_mul(q_conj(q0), level_attitude(yaw_deg)))
    return phi if norm3(phi) > 0.0 else None


def stretched(seg: Move, vehicle: VehicleConfig | None, stretch: bool = True,
               scaled: bool = True) -> Move:
    """A speed-timed move, its travel lengthened to the shortest flyable time if it is
    shorter (`fcu.envelope.feasibility.TimeScaling.shortest`); as it is without a vehicle, when it
    does not move, or when no duration helps; as planned, with its scaling, where not `stretch`
    (`envelope_reason` tells whether it would be), and without it where not `scaled` either."""
    if vehicle is None or not seg.moves or not (stretch or scaled):
        return seg
    scaling = envelope(vehicle).scaling(seg)
    if stretch and scaling.stretches(seg.travel):  # the search's bisection only as needed
        seg = seg.retimed(scaling.shortest())
    seg.scaling = scaling
    return seg


def speed_timed(item: MissionItem) -> bool:
    """Whether `plan_item` times the item's move by a speed (and stretches it)."""
    if item.command == MAV_CMD_NAV_TAKEOFF:
        return not item.param2 > 0.0
    return item.command in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TIME, MAV_CMD_NAV_LAND)


# The parameter that gives the duration of user-timed items.
_TIME_SLOT = {MAV_CMD_POSE_KEYFRAME: "p1", MAV_CMD_FIGURE_EIGHT: "p2", MAV_CMD_NAV_TAKEOFF: "p2"}


def envelope_reason(item: MissionItem, seg: Segment, limits: MissionLimits) -> str:
    """'' when the vehicle can fly the planned segment, else why not (for a person), naming
    the actuator and its limit (`fcu.envelope.feasibility.Envelope.explain`) and the duration that
    would pass, if it is within `limits.item_max_s` (MIS_ITEM_MAX_S); beyond, the reason
    says that no duration up to it flies the item."""
    if limits.vehicle is None or seg.duration <= 0.0 or (isinstance(seg, Move)
                                                          and not seg.moves):
        return ""
    env = envelope(limits.vehicle)
    scaling = seg.scaling if seg.scaling is not None else env.scaling(seg)
    if scaling.fits(seg.duration):  # flown as planned (a stretched move: at its shortest)
        return ""
    slot = _TIME_SLOT.get(item.command)
    if item.command == MAV_CMD_NAV_TAKEOFF and not item.param2 > 0.0:
        slot = None  # timed by the takeoff speed
    if slot is None and scaling.stretches(seg.duration):
        return ""  # planned unstretched (`plan_item`): flown at its shortest, which fits
    excess = scaling.excess(seg.duration)
    shortest = scaling.shortest()
    proposed = math.ceil(shortest * 100.0) / 100.0 if math.isfinite(shortest) else shortest
    if not math.isfinite(shortest):
        hint = "attitude too demanding at any speed"
    elif slot is None:  # cannot happen: speed-timed items are stretched to `shortest`
        hint = "not flyable"
    elif proposed > limits.item_max_s:  # no hint beyond the longest item
        hint = f"not flyable with {slot} up to MIS_ITEM_MAX_S ({limits.item_max_s:g} s)"
    else:
        hint = f"lengthen {slot} to {proposed:.2f} s"
    return f"item {item.seq}: {env.explain(excess)}: {hint}"


# DO_CHANGE_SPEED's speed types (MAVLink's SPEED_TYPE) and the limit each one sets
SPEED_FIELDS = {0: "cruise_speed_m_s", 1: "cruise_speed_m_s", 2: "takeoff_speed_m_s",
                3: "land_speed_m_s"}
SPEED_NO_CHANGE = -1.0
SPEED_DEFAULT = -2.0


def with_speed(item: MissionItem, limits: MissionLimits,
               defaults: MissionLimits) -> MissionLimits:
    """The limits the items after `item` are planned with: a DO_CHANGE_SPEED (p1 speed type:
    air or ground speed set the cruise speed of the legs, climb the take-off speed, descent
    the land speed; p2 the speed in m/s, -1 no change, -2 back to `defaults`, the parameters'
    value; p3, the throttle, ignored) changes one, as PX4 and ArduPilot do for a multicopter;
    any other item leaves them as they are. The legs are stretched by the envelope as at any
    speed (validation checks p1 and p2)."""
    if item.command != MAV_CMD_DO_CHANGE_SPEED or item.param2 == SPEED_NO_CHANGE:
        return limits
    field = SPEED_FIELDS[int(item.param1)]
    speed = float(getattr(defaults, field) if item.param2 == SPEED_DEFAULT else item.param2)
    if field == "cruise_speed_m_s":
        return replace(limits, cruise_speed_m_s=speed)
    if field == "takeoff_speed_m_s":
        return replace(limits, takeoff_speed_m_s=speed)
    return replace(limits, land_speed_m_s=speed)


def _speed_timed(dp: Vec3, speed: float, phi: Vec3 | None,
                 turn_rate: float) -> tuple[Vec3, Vec3 | None, float]:
    """A move's translation and turn with those below the tolerances dropped, and its
    duration: the shortest whose quintic keeps both the speed and the turn rate as top rates,
    1.875 max(distance / speed, turn angle / turn rate) (`QUINTIC_PEAK_RATE`). A speed is a
    most, as PX4's MPC_XY_CRUISE and ArduPilot's WPNAV_SPEED are, never a mean exceeded
    half-way."""
    dist = norm3(dp)
    if dist < POSITION_TOLERANCE_M:
        dp, dist = ZERO, 0.0
    angle = 0.0 if phi is None else norm3(phi)
    if angle < ANGLE_TOLERANCE_RAD:
        phi, angle = None, 0.0
    travel = QUINTIC_PEAK_RATE * dist / speed if dist > 0.0 else 0.0
    if angle > 0.0:
        travel = max(travel, QUINTIC_PEAK_RATE * angle / turn_rate)
    return dp, phi, travel


def plan_item(item: MissionItem, t0: float, p0: Vec3, q0: Quat,
              limits: MissionLimits, stretch: bool = True, scaled: bool = True) -> Segment:
    """The item's segment from (t0, p0, q0); speed-timed moves stretched to what the vehicle
    can fly, or, where not `stretch` (the upload check, whose outcome does not depend on
    how long a stretched move becomes), as planned with their scaling (`envelope_reason`
    then accepts one that the stretch would make fit), or without it where not `scaled`
    either (`envelope_reason` makes it where it is needed)."""
    cmd = item.command
    if cmd == MAV_CMD_DO_CHANGE_SPEED:  # no motion: it changes how later items are planned
        return Move(item.seq, t0, p0, ZERO, q0, None, 0.0, 0.0)
    turn_rate = math.radians(limits.turn_rate_deg_s)
    vehicle = limits.vehicle
    if cmd == MAV_CMD_NAV_TAKEOFF:
        dp = (0.0, 0.0, -item.z - p0[2])
        phi = _turn(q0, item.param4)
        if item.param2 > 0.0:
            return Move(item.seq, t0, p0, dp, q0, phi, item.param2, 0.0)
        dp, phi, travel = _speed_timed(dp, limits.takeoff_speed_m_s, phi, turn_rate)
        return stretched(Move(item.seq, t0, p0, dp, q0, phi, travel, 0.0), vehicle, stretch,
                         scaled)
    if cmd in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TIME):
        target = ned_to_enu((item.x_m, item.y_m, item.z))
        phi = _turn(q0, item.param4) if cmd == MAV_CMD_NAV_WAYPOINT else None
        dp, phi, travel = _speed_timed(_sub(target, p0), limits.cruise_speed_m_s, phi,
                                       turn_rate)
        return stretched(Move(item.seq, t0, p0, dp, q0, phi, travel, item.param1), vehicle,
                         stretch, scaled)
    if cmd == MAV_CMD_NAV_LAND:
        dp, phi, travel = _speed_timed((0.0, 0.0, -p0[2]), limits.land_speed_m_s,
                                       _turn(q0, item.param4), turn_rate)
        return stretched(Move(item.seq, t0, p0, dp, q0, phi, travel, 0.0), vehicle, stretch,
                         scaled)
    if cmd == MAV_CMD_POSE_KEYFRAME:
        target = ned_to_enu((item.x_m, item.y_m, item.z))
        rot = (item.param2, item.param3, item.param4)
        if _floats(*q0, *rot):  # in one compiled call: the same values
            phi, turns, q_end = keyframe_turn(q0, *rot)
            return Move(item.seq, t0, p0, _sub(target, p0), q0, phi if turns else None,
                        item.param1, 0.0, q_end)
        q1 = q_ned_frd_to_enu_flu(q_exp(rot))
        phi = q_log(q_mul(q_conj(q0), q1))  # shortest path
        return Move(item.seq, t0, p0, _sub(target, p0), q0,
                     phi if norm3(phi) > 0.0 else None, item.param1, 0.0)
    if cmd == MAV_CMD_FIGURE_EIGHT:
        axis = ned_to_enu((item.param3, item.param4, item.z))
        return Figure(item.seq, t0, p0, q0, item.param1, item.param2, axis)
    raise ValueError(f"mission item {item.seq}: unsupported command {cmd}")

