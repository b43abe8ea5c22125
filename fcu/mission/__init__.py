"""Mission validation and execution without I/O: mission items in, a timed `Reference` out.

Items travel as MAVLink local NED / body FRD (`common.wire.mission_items.MissionItem`), or in a
global frame that the vehicle's home position converts to local NED (`check_mission`,
`localize`); inside, everything is world ENU / body FLU. Every item starts where the
previous item's *desired* pose ended (never the measured pose), and has fixed start and end
times planned when the mission starts, so the timeline is exact and a mission that
re-creates a trajectory (Case I, see `gcs.run.scenario_mission`) gives the trajectory's
reference to rounding.

Time comes in as arguments (seconds); nothing here reads a clock. The MAVLink numbers used
(`fcu.mission.codes`) are common.xml's, taken from `common.wire.mav_enums`, so that the package
imports no MAVLink library (tests/unit/test_mav_enums.py checks the enums against pymavlink).

Item semantics (positions local NED, metres; yaw in degrees, NED; NaN yaw = keep attitude):

* NAV_TAKEOFF (22): climb vertically from the start pose to NED z; p2 = duration (0: at up
  to the takeoff speed), p4 = yaw (finite: level attitude at that yaw, same profile).
* NAV_WAYPOINT (16): travel to x, y, z at up to the cruise speed, then hold p1 seconds;
  p4 = yaw.
* NAV_LOITER_TIME (19): travel to x, y, z as a waypoint, then hold p1 seconds.
* NAV_LAND (21): descend vertically to NED z = 0 at up to the land speed; p4 = yaw.
* POSE_KEYFRAME (31000): reach x, y, z and the attitude q_ned_frd = exp(p2, p3, p4) in p1 s.
* FIGURE_EIGHT (31001): the figure-infinity of the paper's eq. (31)-(32) with amplitude p1,
  duration p2, attitude turning about the world axis (p3, p4, z) (NED, not normalised).

Travel, climbs and descents follow the minimum-jerk quintic (zero velocity and acceleration at
both ends); attitudes move along the shortest rotation with the same profile. A speed (or the
turn rate) is the quintic's top rate: a move timed by it lasts 1.875 distance / speed
(`fcu.mission.planning`), as PX4 and ArduPilot take their cruise speeds as top speeds. The
quintic and the figure-infinity are those of `fcu.reference.trajectory` (one copy of the maths).
An item is active on [start, end): at a boundary the reference is the next item's at tau = 0,
the right-hand limit that holds over the coming control period (at a figure's start, T'' = pi
k^2 at once). A move whose duration comes from a speed (not from a parameter) and whose distance
is below `POSITION_TOLERANCE_M` (or whose turn is below `ANGLE_TOLERANCE_RAD`) is not made: the
item keeps the start position (attitude), so a target equal to the previous item's end up to the
wire's resolution costs no travel. A requested yaw change makes the move last at least 1.875
angle / turn rate.

Flyable missions (`fcu.envelope.feasibility`, when `MissionLimits.vehicle` is given): every planned
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

The parts: `codes` (the MAVLink numbers), `limits` (`MissionLimits`), `validation`
(`check_mission`, `localize`), `segments` (the planned moves and figures), `planning` (one
item's segment, stretched or explained) and `executor` (`MissionExecutor`).
"""
