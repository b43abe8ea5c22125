"""Mission validation and execution without I/O: mission items in, a timed `Reference` out.

Items travel as MAVLink local NED / body FRD (`common.mission_items.MissionItem`), or in a
global frame that the vehicle's home position converts to local NED (`check_mission`,
`localize`); inside, everything is world ENU / body FLU. Every item starts where the
previous item's *desired* pose ended (never the measured pose), and has fixed start and end
times planned when the mission starts, so the timeline is exact and a mission that
re-creates a trajectory (Case I, see `gcs.scenario_mission`) gives the trajectory's
reference to rounding.

Time comes in as arguments (seconds); nothing here reads a clock. The MAVLink numbers used
below are those of common.xml, written out so that this module imports no MAVLink library
(tests/unit/test_mission.py checks them against pymavlink).

Item semantics (positions local NED, metres; yaw in degrees, NED; NaN yaw = keep attitude):

* NAV_TAKEOFF (22): climb vertically from the start pose to NED z; p2 = duration (0: |dz| /
  takeoff speed), p4 = yaw (finite: level attitude at that yaw, same profile).
* NAV_WAYPOINT (16): travel to x, y, z in distance / cruise speed, then hold p1 seconds;
  p4 = yaw.
* NAV_LOITER_TIME (19): travel to x, y, z as a waypoint, then hold p1 seconds.
* NAV_LAND (21): descend vertically to NED z = 0 in |z| / land speed; p4 = yaw.
* POSE_KEYFRAME (31000): reach x, y, z and the attitude q_ned_frd = exp(p2, p3, p4) in p1 s.
* FIGURE_EIGHT (31001): the figure-infinity of the paper's eq. (31)-(32) with amplitude p1,
  duration p2, attitude turning about the world axis (p3, p4, z) (NED, not normalised).

Travel, climbs and descents follow the minimum-jerk quintic (zero velocity and acceleration
at both ends); attitudes move along the shortest rotation with the same profile. The quintic
and the figure-infinity are those of `fcu.trajectory` (one copy of the maths). An item is
active on [start, end): at a boundary the reference is the next item's at tau = 0, the
right-hand limit that holds over the coming control period (at a figure's start, T'' = pi k^2
at once). A move
whose duration comes from a speed (not from a parameter) and whose distance is below
`POSITION_TOLERANCE_M` (or whose turn is below `ANGLE_TOLERANCE_RAD`) is not made: the item
keeps the start position (attitude), so a target equal to the previous item's end up to the
wire's resolution costs no travel. A requested yaw change makes the move last at least
angle / turn rate.

Flyable missions (`fcu.feasibility`, when `MissionLimits.vehicle` is given): every planned
segment's nominal wrench must allocate to commands every actuator can follow at every sample:
rotor speeds within `feasibility.MARGIN` w_max with their lag, tilt rates within
`feasibility.TILT_MARGIN` of the servos' rate limit. Items whose duration comes from a speed
(NAV_WAYPOINT and NAV_LOITER_TIME travel, NAV_TAKEOFF with p2 = 0, NAV_LAND) are STRETCHED:
their travel takes the shortest time that passes the check whenever distance / speed (or the
turn time) is shorter, and the planned timeline uses that time, both when a mission is
validated and when `MissionExecutor` plans it, so the upload check and the flight agree. Items
whose duration the user gave (POSE_KEYFRAME p1, NAV_TAKEOFF p2 > 0, FIGURE_EIGHT p2) keep it,
and a mission with one that fails is REFUSED (MAV_MISSION_DENIED) with a reason naming the
item, the actuator and its limit, and the duration that would pass (`check_mission`).
Validation plans from the origin at the identity attitude (as the geofence does); the executor
re-plans from the actual start pose with the same stretching rule, never refuses (a user-timed
item that no longer fits from there flies as given) and keeps the speed-derived time of a move
that no duration can make flyable (hovering at one of its attitudes already exceeds the margin;
validation refuses those).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from common.config import VehicleConfig
from common.frames import ned_to_enu, q_ned_frd_to_enu_flu
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
from fcu.dualquat import Q_IDENTITY, Quat, Vec3, norm3, q_conj, q_exp, q_log, q_mul
from fcu.feasibility import TimeScaling, envelope, figure_instants, move_instants
from fcu.tracker import Reference, pose_ref
from fcu.trajectory import FigureInfinity, q_exp_many, quintic, quintic_poly

# MAV_FRAME, MAV_CMD and MAV_MISSION_RESULT values (common.xml).
MAV_FRAME_LOCAL_NED = 1
MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LOITER_TIME = 19
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_POSE_KEYFRAME = 31000  # MAV_CMD_WAYPOINT_USER_1
MAV_CMD_FIGURE_EIGHT = 31001  # MAV_CMD_WAYPOINT_USER_2
SUPPORTED_COMMANDS = frozenset({MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT,
                                MAV_CMD_NAV_LOITER_TIME, MAV_CMD_NAV_LAND,
                                MAV_CMD_POSE_KEYFRAME, MAV_CMD_FIGURE_EIGHT})

# Item ends are sums of float seconds; the flight clock is integer microseconds. An item
# that ends at a step's instant ends at that step whatever the rounding of the sum.
TIME_EPS_S = 1e-9
MAV_MISSION_ACCEPTED = 0
MAV_MISSION_UNSUPPORTED_FRAME = 2
MAV_MISSION_UNSUPPORTED = 3
MAV_MISSION_NO_SPACE = 4
MAV_MISSION_INVALID_PARAM1 = 6
MAV_MISSION_INVALID_PARAM2 = 7
MAV_MISSION_INVALID_PARAM3 = 8
MAV_MISSION_INVALID_PARAM4 = 9
MAV_MISSION_INVALID_PARAM5_X = 10
MAV_MISSION_INVALID_PARAM6_Y = 11
MAV_MISSION_INVALID_PARAM7 = 12
MAV_MISSION_INVALID_SEQUENCE = 13
MAV_MISSION_DENIED = 14

FIGURE_EXTENT = math.sqrt(5.0)  # max |[sin 2T, sin T, 1 - cos 2T]|
# MAVProxy's `wp load` scales local x, y by 1e7 instead of 1e4: 1 m in a file arrives as
# 1000 m. A local item this far out and beyond the geofence is refused with that hint.
SCALED_LOCAL_M = 1000.0
POSITION_TOLERANCE_M = 1e-3  # well above the wire's resolution (1e-4 m for x, y; float32 z)
ANGLE_TOLERANCE_RAD = 1e-4

_ZERO: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MissionLimits:
    """What a mission may ask for, and the speeds of the items that have no duration.

    `vehicle`: the airframe whose actuator envelope missions must respect (items stretched
    or refused, module docstring); None skips that check."""

    max_items: int = 500
    max_distance_m: float = 1000.0  # geofence: radius around the origin
    cruise_speed_m_s: float = 2.0
    land_speed_m_s: float = 0.5
    takeoff_speed_m_s: float = 1.0
    turn_rate_deg_s: float = 30.0  # yaw changes of speed-timed items take at least this long
    vehicle: VehicleConfig | None = None

    def __post_init__(self) -> None:
        for name in ("max_distance_m", "cruise_speed_m_s", "land_speed_m_s",
                     "takeoff_speed_m_s", "turn_rate_deg_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"MissionLimits.{name} must be finite and > 0, got {value}")
        if self.max_items < 0:
            raise ValueError(f"MissionLimits.max_items must be >= 0, got {self.max_items}")


class MissionEvent(NamedTuple):
    kind: str  # "current" | "reached" | "completed"
    seq: int


class MissionCheck(NamedTuple):
    """The outcome of validating a mission."""

    result: int  # MAV_MISSION_RESULT
    seq: int | None  # the offending item, if any
    reason: str = ""  # why, for a person: set for MAV_MISSION_DENIED, else ""


# ----------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------


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
    (50% of 4.0): lengthen p1 to 2.31 s" (module docstring). Items are checked in order: the first
    failing item is reported.
    """
    if len(items) > limits.max_items:
        return MissionCheck(MAV_MISSION_NO_SPACE, None)
    return _check_items(items, limits, geofence=True, envelope_check=limits.vehicle is not None,
                        home=home)


def validate_mission(items: Sequence[MissionItem], limits: MissionLimits,
                     home: HomePosition | None = None) -> tuple[int, int | None]:
    """(MAV_MISSION_RESULT, offending seq or None) of `check_mission`."""
    check = check_mission(items, limits, home)
    return check.result, check.seq


def _check_items(items: Sequence[MissionItem], limits: MissionLimits, geofence: bool,
                 envelope_check: bool = False,
                 home: HomePosition | None = None) -> MissionCheck:
    pos = [0.0, 0.0, 0.0]
    t, p, q = 0.0, _ZERO, Q_IDENTITY
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
            seg = _plan_item(item, t, p, q, limits)
            reason = _envelope_reason(item, seg, limits)
            if reason:
                return MissionCheck(MAV_MISSION_DENIED, item.seq, reason)
            t, p, q = seg.t1, seg.p_end, seg.q_end
    return MissionCheck(MAV_MISSION_ACCEPTED, None)


# ----------------------------------------------------------------------------------------
# Segments: one planned item each, sampled at tau = t - t0
# ----------------------------------------------------------------------------------------


def level_attitude(yaw_ned_deg: float) -> Quat:
    """Level attitude (ENU/FLU) heading at a NED yaw in degrees."""
    return q_ned_frd_to_enu_flu(q_exp((0.0, 0.0, math.radians(yaw_ned_deg))))


class _Segment:
    """Base: planned start/end time, start and end pose; `duration` is the part that moves
    (the rest, if any, holds the end pose)."""

    seq: int
    t0: float
    t1: float
    duration: float
    p_end: Vec3
    q_end: Quat
    end_ref: Reference
    scaling: TimeScaling | None = None  # set where the envelope has been evaluated

    def sample(self, tau: float) -> Reference:  # pragma: no cover - overridden
        raise NotImplementedError

    def path(self, sigma: np.ndarray) -> Reference:  # pragma: no cover - overridden
        """The moving part flown in 1 s, at normalised times sigma (arrays)."""
        raise NotImplementedError

    def instants(self) -> np.ndarray:  # pragma: no cover - overridden
        """Normalised times at which the envelope is checked."""
        raise NotImplementedError


class _Move(_Segment):
    """Quintic move p0 -> p0 + dp, q0 -> q0 exp(phi) in `travel` s, then hold `hold` s."""

    def __init__(self, seq: int, t0: float, p0: Vec3, dp: Vec3, q0: Quat, phi: Vec3 | None,
                 travel: float, hold: float) -> None:
        self.seq, self.t0 = seq, t0
        self.p0, self.dp, self.q0, self.phi = p0, dp, q0, phi
        self.travel = self.duration = travel
        self.hold = hold
        self.t1 = t0 + travel + hold
        self.p_end = (p0[0] + dp[0], p0[1] + dp[1], p0[2] + dp[2])
        self.q_end = q0 if phi is None else q_mul(q0, q_exp(phi))
        self.end_ref = pose_ref(self.p_end, self.q_end)

    def retimed(self, travel: float) -> _Move:
        return _Move(self.seq, self.t0, self.p0, self.dp, self.q0, self.phi, travel, self.hold)

    def _at(self, s: Any, ds: Any, dds: Any, d: float, many: bool = False) -> Reference:
        p0, dp = self.p0, self.dp
        p = (p0[0] + s * dp[0], p0[1] + s * dp[1], p0[2] + s * dp[2])
        # Same association as FigureEight's rise: h * s' / T, h * s'' / (T T).
        v = (dp[0] * ds / d, dp[1] * ds / d, dp[2] * ds / d)
        d2 = d * d
        a = (dp[0] * dds / d2, dp[1] * dds / d2, dp[2] * dds / d2)
        phi = self.phi
        if phi is None:
            return Reference(p, self.q0, v, a, _ZERO, _ZERO)
        # q = q0 exp(s phi): body rate s' phi (phi commutes with exp(s phi)), derivative s'' phi.
        rot = (s * phi[0], s * phi[1], s * phi[2])
        q = q_mul(self.q0, q_exp_many(*rot) if many else q_exp(rot))
        w = (phi[0] * ds / d, phi[1] * ds / d, phi[2] * ds / d)
        wd = (phi[0] * dds / d2, phi[1] * dds / d2, phi[2] * dds / d2)
        return Reference(p, q, v, a, w, wd)

    def sample(self, tau: float) -> Reference:
        d = self.travel
        if tau >= d:
            return self.end_ref
        return self._at(*quintic(tau / d), d)

    def path(self, sigma: np.ndarray) -> Reference:
        return self._at(*quintic_poly(sigma), 1.0, many=True)

    def instants(self) -> np.ndarray:
        return move_instants(0.0 if self.phi is None else norm3(self.phi))

    @property
    def moves(self) -> bool:
        return self.travel > 0.0 and (self.phi is not None or any(self.dp))


class _Figure(_Segment):
    """The figure-infinity (`fcu.trajectory.FigureInfinity`) from (p0, q0), t0 on."""

    def __init__(self, seq: int, t0: float, p0: Vec3, q0: Quat, amp: float, duration: float,
                 axis_enu: Vec3) -> None:
        self.seq, self.t0 = seq, t0
        self.figure = FigureInfinity(amp, duration, axis_enu, p0, q0)
        self.duration = duration
        self.t1 = t0 + duration
        self.end_ref = self.figure.end
        self.p_end, self.q_end = self.end_ref.p_enu_m, self.end_ref.q_enu_flu

    def phase(self, tau: float) -> tuple[float, float, float]:
        return self.figure.phase(tau)

    def sample(self, tau: float) -> Reference:
        return self.figure.sample(tau)

    def path(self, sigma: np.ndarray) -> Reference:
        return FigureInfinity(self.figure.amp, 1.0, self.figure.n, self.figure.p0,
                              self.figure.q0).path(sigma)

    def instants(self) -> np.ndarray:
        return figure_instants(norm3(self.figure.n), self.figure.phase_instants)


def _sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _turn(q0: Quat, yaw_deg: float) -> Vec3 | None:
    """Rotation vector from q0 to the level attitude at yaw_deg (None: keep the attitude)."""
    if math.isnan(yaw_deg):
        return None
    phi = q_log(q_mul(q_conj(q0), level_attitude(yaw_deg)))
    return phi if norm3(phi) > 0.0 else None


def _stretched(seg: _Move, vehicle: VehicleConfig | None) -> _Move:
    """A speed-timed move, its travel lengthened to the shortest flyable time if it is
    shorter (`fcu.feasibility.TimeScaling.shortest`); as it is without a vehicle, when it does
    not move, or when no duration helps."""
    if vehicle is None or not seg.moves:
        return seg
    scaling = envelope(vehicle).scaling(seg)
    shortest = scaling.shortest()
    if math.isfinite(shortest) and shortest > seg.travel:
        seg = seg.retimed(shortest)
    seg.scaling = scaling
    return seg


# The parameter that gives the duration of user-timed items.
_TIME_SLOT = {MAV_CMD_POSE_KEYFRAME: "p1", MAV_CMD_FIGURE_EIGHT: "p2", MAV_CMD_NAV_TAKEOFF: "p2"}


def _envelope_reason(item: MissionItem, seg: _Segment, limits: MissionLimits) -> str:
    """'' when the vehicle can fly the planned segment, else why not (for a person), naming
    the actuator and its limit (`fcu.feasibility.Envelope.explain`)."""
    if limits.vehicle is None or seg.duration <= 0.0 or (isinstance(seg, _Move)
                                                          and not seg.moves):
        return ""
    env = envelope(limits.vehicle)
    scaling = seg.scaling if seg.scaling is not None else env.scaling(seg)
    excess = scaling.excess(seg.duration)
    if excess.ratio <= 1.0:  # flown as planned (a stretched move: at its shortest)
        return ""
    shortest = scaling.shortest()
    slot = _TIME_SLOT.get(item.command)
    if item.command == MAV_CMD_NAV_TAKEOFF and not item.param2 > 0.0:
        slot = None  # timed by the takeoff speed
    if not math.isfinite(shortest):
        hint = "attitude too demanding at any speed"
    elif slot is None:  # cannot happen: speed-timed items are stretched to `shortest`
        hint = "not flyable"
    else:
        hint = f"lengthen {slot} to {math.ceil(shortest * 100.0) / 100.0:.2f} s"
    return f"item {item.seq}: {env.explain(excess)}: {hint}"


def _plan_item(item: MissionItem, t0: float, p0: Vec3, q0: Quat,
               limits: MissionLimits) -> _Segment:
    cmd = item.command
    turn_rate = math.radians(limits.turn_rate_deg_s)

    def speed_timed(dp: Vec3, speed: float, phi: Vec3 | None) -> tuple[Vec3, Vec3 | None, float]:
        """Drop moves below the tolerances; duration = max(distance / speed, turn time)."""
        dist = norm3(dp)
        if dist < POSITION_TOLERANCE_M:
            dp, dist = _ZERO, 0.0
        angle = 0.0 if phi is None else norm3(phi)
        if angle < ANGLE_TOLERANCE_RAD:
            phi, angle = None, 0.0
        travel = dist / speed if dist > 0.0 else 0.0
        if angle > 0.0:
            travel = max(travel, angle / turn_rate)
        return dp, phi, travel

    def move(dp: Vec3, phi: Vec3 | None, travel: float, hold: float) -> _Move:
        """A speed-timed move, stretched to what the vehicle can fly."""
        return _stretched(_Move(item.seq, t0, p0, dp, q0, phi, travel, hold), limits.vehicle)

    if cmd == MAV_CMD_NAV_TAKEOFF:
        dp = (0.0, 0.0, -item.z - p0[2])
        phi = _turn(q0, item.param4)
        if item.param2 > 0.0:
            return _Move(item.seq, t0, p0, dp, q0, phi, item.param2, 0.0)
        dp, phi, travel = speed_timed(dp, limits.takeoff_speed_m_s, phi)
        return move(dp, phi, travel, 0.0)
    if cmd in (MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TIME):
        target = ned_to_enu((item.x_m, item.y_m, item.z))
        phi = _turn(q0, item.param4) if cmd == MAV_CMD_NAV_WAYPOINT else None
        dp, phi, travel = speed_timed(_sub(target, p0), limits.cruise_speed_m_s, phi)
        return move(dp, phi, travel, item.param1)
    if cmd == MAV_CMD_NAV_LAND:
        dp, phi, travel = speed_timed((0.0, 0.0, -p0[2]), limits.land_speed_m_s,
                                      _turn(q0, item.param4))
        return move(dp, phi, travel, 0.0)
    if cmd == MAV_CMD_POSE_KEYFRAME:
        target = ned_to_enu((item.x_m, item.y_m, item.z))
        q1 = q_ned_frd_to_enu_flu(q_exp((item.param2, item.param3, item.param4)))
        phi = q_log(q_mul(q_conj(q0), q1))  # shortest path
        return _Move(item.seq, t0, p0, _sub(target, p0), q0,
                     phi if norm3(phi) > 0.0 else None, item.param1, 0.0)
    if cmd == MAV_CMD_FIGURE_EIGHT:
        axis = ned_to_enu((item.param3, item.param4, item.z))
        return _Figure(item.seq, t0, p0, q0, item.param1, item.param2, axis)
    raise ValueError(f"mission item {item.seq}: unsupported command {cmd}")


# ----------------------------------------------------------------------------------------
# Executor
# ----------------------------------------------------------------------------------------


class MissionExecutor:
    """Plans a mission on a fixed timeline and samples its reference.

    `start` (or `set_current`) plans every remaining item at once: item k starts at the
    end time of item k - 1, from its desired end pose; with `limits.vehicle`, speed-timed
    items are stretched as in validation (module docstring). An item is active on
    [start, end), so at a boundary the sample is the next item's at tau = 0 (the right-hand
    limit); zero-length items are passed through (their events still come). Before the start
    the reference holds the start pose, after the end the final pose.
    """

    def __init__(self, items: Sequence[MissionItem], limits: MissionLimits) -> None:
        self.items = tuple(items)
        self.limits = limits
        if not self.items:
            raise ValueError("empty mission")
        # The geofence and the item count are the uploader's business (the vehicle may have
        # tightened its limits since); what cannot be flown is refused here.
        result, seq, _ = _check_items(self.items, limits, geofence=False)
        if result != MAV_MISSION_ACCEPTED:
            raise ValueError(f"mission item {seq}: not executable (MAV_MISSION_RESULT {result})")
        self._segments: list[_Segment] = []
        self._ends: list[float] = []
        self._start_ref: Reference | None = None
        self._t_start = 0.0
        self._announced = 0
        self._reached = 0
        self._completed = False
        self.current_seq = 0

    # ------------------------------------------------------------------ planning

    def start(self, t_s: float, p_enu_m: Vec3, q_enu_flu: Quat) -> None:
        """Plan the whole mission from item 0, starting at t_s from the given pose."""
        self.set_current(0, t_s, p_enu_m, q_enu_flu)

    def set_current(self, seq: int, t_s: float, p_enu_m: Vec3, q_enu_flu: Quat) -> None:
        """Re-plan from item seq, starting at t_s from the given pose."""
        if not 0 <= seq < len(self.items):
            raise ValueError(f"no mission item {seq} (mission has {len(self.items)})")
        p, q = tuple(p_enu_m), tuple(q_enu_flu)
        self._start_ref = pose_ref(p, q)  # type: ignore[arg-type]
        self._t_start = t_s
        segments: list[_Segment] = []
        t = t_s
        for item in self.items[seq:]:
            seg = _plan_item(item, t, p, q, self.limits)  # type: ignore[arg-type]
            segments.append(seg)
            t, p, q = seg.t1, seg.p_end, seg.q_end
        self._segments = segments
        self._ends = [seg.t1 for seg in segments]
        self._announced = 0
        self._reached = 0
        self._completed = False
        self.current_seq = seq

    @property
    def started(self) -> bool:
        return self._start_ref is not None

    @property
    def completed(self) -> bool:
        """True once `update` has seen the last item end."""
        return self._completed

    @property
    def schedule(self) -> tuple[tuple[int, float, float], ...]:
        """(seq, planned start, planned end) of each planned item."""
        return tuple((seg.seq, seg.t0, seg.t1) for seg in self._segments)

    @property
    def end_time_s(self) -> float:
        self._require_started()
        return self._ends[-1]

    def _require_started(self) -> None:
        if self._start_ref is None:
            raise RuntimeError("mission executor not started")

    # ------------------------------------------------------------------ running

    def update(self, t_s: float) -> list[MissionEvent]:
        """Events since the last update: items that became current, were reached, the end."""
        self._require_started()
        segs = self._segments
        events: list[MissionEvent] = []
        while True:
            if self._reached < self._announced:
                seg = segs[self._reached]
                if seg.t1 <= t_s + TIME_EPS_S:
                    events.append(MissionEvent("reached", seg.seq))
                    self._reached += 1
                    continue
                break
            if self._announced < len(segs) and segs[self._announced].t0 <= t_s + TIME_EPS_S:
                seg = segs[self._announced]
                events.append(MissionEvent("current", seg.seq))
                self.current_seq = seg.seq
                self._announced += 1
                continue
            break
        if self._reached == len(segs) and not self._completed:
            self._completed = True
            events.append(MissionEvent("completed", segs[-1].seq))
        return events

    def sample(self, t_s: float) -> Reference:
        """The reference at t_s (any time: before the start, during, after the end)."""
        self._require_started()
        if t_s < self._t_start:
            return self._start_ref  # type: ignore[return-value]
        k = bisect.bisect_right(self._ends, t_s)
        if k == len(self._segments):
            return self._segments[-1].end_ref
        seg = self._segments[k]
        return seg.sample(t_s - seg.t0)
