"""The commander stage: arming, modes and which reference flies (mission, offboard, hold,
land, takeoff, return, position control), without I/O.

Time comes in as arguments: `t_us` is the flight clock (simulated in lockstep, monotonic in
real time) for everything that shapes the flight; `now_s` is the wall clock, used only for
the offboard stream's freshness (DESIGN.md section 2). What the commander says goes into
`events` (on the flight clock); the process shell turns them into STATUSTEXT.

Landing (LAND mode, or a mission whose last item is NAV_LAND): the descent to the ground
plane follows its planned profile; then the set-point keeps going down at the land speed
(at most `TOUCHDOWN_DEPTH_M` below the planned end) so the vehicle reaches the ground
whatever its tracking error, and the land detector disarms once the vehicle has been still
for `LANDED_STILL_S` (or rests below `LANDED_ALTITUDE_M`): a landing ends on the ground,
disarmed, never hovering armed.

TAKEOFF climbs `FlightSettings.takeoff_alt_m` (MIS_TAKEOFF_ALT) straight up from where the
vehicle should be, then holds (HOLD). RTL climbs to `rtl_return_alt_m` (RTL_RETURN_ALT)
above home if it is lower, flies to home's north and east at `rtl_cruise_m_s` (MPC_XY_CRUISE)
and lands there as LAND does. Both are planned as missions (NAV_TAKEOFF, NAV_WAYPOINT,
NAV_LAND items) by the mission executor, so their legs are quintic profiles stretched until
the vehicle can fly them (`fcu.mission`, `fcu.feasibility`). Home is the origin of the local
frame (HOME_POSITION). POSCTL moves the set-point as MANUAL_CONTROL's sticks say
(`fcu.manual`); the stream's freshness is checked on the wall clock like the offboard one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

from common.frames import frd_to_flu, ned_to_enu, q_ned_frd_to_enu_flu
from common.mission_items import MissionItem
from common.modes import Mode
from common.outcome import CRASH, FAILSAFE, INFO, Event
from fcu import approach, manual, offboard
from fcu.dualquat import Q_IDENTITY, Quat, Vec3, norm3
from fcu.feasibility import Envelope, envelope
from fcu.manual import ManualSetpoint, StickSettings
from fcu.mission.executor import MissionEvent, MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.segments import level_attitude
from fcu.tracker import Reference, VehicleState, pose_ref

_ZERO: Vec3 = (0.0, 0.0, 0.0)
# MAVLink numbers (common.xml), written out so that this stage imports no MAVLink library.
MAV_RESULT_ACCEPTED, MAV_RESULT_DENIED = 0, 2
SEVERITY_EMERGENCY, SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_INFO = 0, 2, 4, 6
MAV_FRAME_LOCAL_NED, MAV_CMD_NAV_LAND = 1, 21
MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_TAKEOFF = 16, 22
FORCE_DISARM_MAGIC = 21196.0  # MAV_CMD_COMPONENT_ARM_DISARM p2 that forces a disarm
LANDED_ALTITUDE_M = 0.05
TAKEOFF_ALTITUDE_M = 0.1
LANDED_SPEED_M_S = 0.2
LANDED_STILL_S = 0.3
LANDED_LIFT_RATIO = 0.9
TOUCHDOWN_DEPTH_M = 1.0
TOUCHDOWN_BLOCKED_M = 0.1
# Offboard targets beyond these are refused (no vehicle of this class flies them).
MAX_OFFBOARD_SPEED_M_S = 50.0
MAX_OFFBOARD_ACC_M_S2 = 50.0
MAX_OFFBOARD_RATE_RAD_S = 50.0


@dataclass(frozen=True)
class FlightSettings:
    """The automatic modes' and POSCTL's parameters (PX4's names)."""

    takeoff_alt_m: float = 2.5  # MIS_TAKEOFF_ALT: TAKEOFF climbs this much
    rtl_return_alt_m: float = 10.0  # RTL_RETURN_ALT: RTL climbs to this height above home
    rtl_cruise_m_s: float = 5.0  # MPC_XY_CRUISE: RTL's travel speed
    manual_timeout_s: float = 0.5  # COM_RC_LOSS_T: POSCTL without MANUAL_CONTROL -> HOLD
    sticks: StickSettings = field(default_factory=StickSettings)


class Touchdown(NamedTuple):
    """The last phase of a landing: the set-point sinks from (p, q) from t_us on."""

    t_us: int
    p_enu_m: Vec3
    q_enu_flu: Quat


@dataclass
class OffboardSetpoint:
    """The latest offboard targets, converted to ENU/FLU; None = not given."""

    p_enu_m: Vec3 | None = None
    v_enu_m_s: Vec3 = _ZERO
    a_enu_m_s2: Vec3 = _ZERO
    yaw_ned_rad: float | None = None
    q_enu_flu: Quat | None = None
    omega_flu_rad_s: Vec3 = _ZERO
    received_s: float = -math.inf
    seq: int = 0  # counts the samples taken: the reference anchors each new one

    def target(self) -> offboard.Target:
        """The sample as the shaper takes it: the attitude given, or level at the yaw given,
        or None (keep the attitude)."""
        q = self.q_enu_flu
        if q is None and self.yaw_ned_rad is not None:
            q = level_attitude(math.degrees(self.yaw_ned_rad))
        return offboard.Target(self.seq, self.p_enu_m, self.v_enu_m_s, self.a_enu_m_s2, q,
                               self.omega_flu_rad_s)


class Commander:
    """Arming, modes, the mission executor, offboard, hold and land references."""

    def __init__(self, limits: MissionLimits, offboard_timeout_s: float = 1.0,
                 flight: FlightSettings | None = None) -> None:
        self.limits = limits
        self.offboard_timeout_s = offboard_timeout_s
        self.flight = flight or FlightSettings()
        approach.warm()  # OFFBOARD's and HOLD's planner: compiled before the first period
        self.armed = False
        self.mode = Mode.HOLD
        self.flight_started = False  # lockstep: simulated time runs once this latches
        self.mission: tuple[MissionItem, ...] = ()
        self.mission_current = 0  # the one home of the current mission item
        self.executor: MissionExecutor | None = None
        self.mission_running = False
        self.mission_done = False
        self.hold: Reference | None = None
        self.land: MissionExecutor | None = None
        self.auto: MissionExecutor | None = None  # TAKEOFF's or RTL's plan
        self.touchdown: Touchdown | None = None
        self.offboard = OffboardSetpoint()
        self.sticks = manual.CENTRED  # the latest MANUAL_CONTROL
        self.sticks_received_s = -math.inf  # wall clock; -inf: never
        self.manual_sp: ManualSetpoint | None = None  # POSCTL's set-point (None: from here)
        self.manual_limits: StickSettings = self.flight.sticks  # fitted to the vehicle
        self.offboard_sp: offboard.Shaped | None = None  # OFFBOARD's shaper (None: from here)
        self._offboard_refused = ""  # the last refusal said
        # HOLD brakes to `hold` (where the reference stops) with the same shaper
        self.hold_sp: offboard.Shaped | None = None
        self._hold_shaped: Reference | None = None  # the hold that hold_sp brakes to
        self.state: VehicleState | None = None
        self.last_ref: Reference | None = None
        self.clock_us = 0  # the flight clock at the latest input (events are stamped with it)
        self.events: list[Event] = []
        self.mission_events: list[MissionEvent] = []
        self.still_since_us: int | None = None
        self.on_ground = True  # the landed state (`update_landed`)

    # ------------------------------------------------------------------ outputs

    def say(self, severity: int, text: str, kind: str = INFO) -> None:
        self.events.append(Event(self.clock_us, severity, text[:50], kind))

    @property
    def landed(self) -> bool:
        """On the ground, as the landed state machine (`update_landed`) last concluded."""
        return self.on_ground

    def update_landed(self) -> None:
        """The landed state at each new state (PX4's land detector, simplified): a disarmed
        vehicle at rest at ground level is on the ground; an armed one leaves it when it
        rises or moves, and comes back to it only through `land_detector` (a touchdown with
        the vehicle still, held up and lifting little), never from its altitude alone: with
        no ground below (Case II) a hover at z = 0 is not a landing."""
        s = self.state
        if s is None:
            return
        speed = math.sqrt(sum(v * v for v in s.v_flu_m_s))
        if not self.armed:
            self.on_ground = s.p_enu_m[2] < LANDED_ALTITUDE_M and speed < LANDED_SPEED_M_S
        elif self.on_ground and (s.p_enu_m[2] > TAKEOFF_ALTITUDE_M or
                                 speed > LANDED_SPEED_M_S):
            self.on_ground = False

    def _current_pose_ref(self) -> Reference:
        """Where the vehicle should be now: the last desired pose in flight, else the state."""
        if self.armed and self.last_ref is not None:
            return pose_ref(self.last_ref.p_enu_m, self.last_ref.q_enu_flu)
        if self.state is None:
            return pose_ref(_ZERO, Q_IDENTITY)
        return pose_ref(self.state.p_enu_m, self.state.q_enu_flu)

    # ------------------------------------------------------------------ commands

    def arm(self) -> tuple[int, str]:
        if self.armed:
            return MAV_RESULT_ACCEPTED, "already armed"
        if self.state is None:
            return MAV_RESULT_DENIED, "arming refused: no state input"
        self.last_ref = None  # hold where the vehicle is, not where an old reference was
        self.armed = True
        self.hold = self._current_pose_ref()
        self.touchdown = None
        self.manual_sp = None  # POSCTL starts from where the vehicle is
        self.say(SEVERITY_INFO, "armed")
        if self.mode == Mode.MISSION and not self.mission_running and not self.mission_done:
            self._start_mission()  # MISSION_START came first: fly it now
        self._maybe_start_flight()
        return MAV_RESULT_ACCEPTED, "armed"

    def disarm(self, force: bool = False, reason: str = "disarmed",
               record_in_air: bool = True) -> tuple[int, str]:
        """Disarm; in the air only with `force`, and then recorded as a crash unless the
        caller records the cause itself (`record_in_air=False`: divergence)."""
        if not self.armed:
            return MAV_RESULT_ACCEPTED, "already disarmed"
        landed = self.landed
        if not force and not landed:
            return MAV_RESULT_DENIED, "disarm refused: in the air (force with p2 = 21196)"
        self.armed = False  # simulated time keeps running once the flight has started
        self.mission_running = False
        self.touchdown = None
        self.land = None
        self.auto = None
        self.say(SEVERITY_INFO if not force else SEVERITY_WARNING, reason)
        if not landed and record_in_air:
            self.say(SEVERITY_CRITICAL, "disarmed in the air", CRASH)
        return MAV_RESULT_ACCEPTED, reason

    def set_mode(self, mode: Mode, now_s: float) -> tuple[int, str]:
        if mode == Mode.MISSION and not self.mission:
            return MAV_RESULT_DENIED, "no mission"
        if mode == Mode.OFFBOARD and (
                self.offboard.received_s + self.offboard_timeout_s < now_s
                or (self.offboard.p_enu_m is None and self.offboard.q_enu_flu is None)):
            return MAV_RESULT_DENIED, "offboard refused: no setpoint stream"
        if mode == Mode.LAND and not self.armed:
            return MAV_RESULT_DENIED, "land: not armed"
        if mode in (Mode.TAKEOFF, Mode.RTL) and not self.armed:
            return MAV_RESULT_DENIED, f"{mode.name.lower()}: not armed"
        if mode == Mode.POSCTL and not self.manual_fresh(now_s):
            return MAV_RESULT_DENIED, "POSCTL refused: no MANUAL_CONTROL"
        previous = self.mode
        idle = self.auto is None and self.touchdown is None  # e.g. landed, disarmed, re-armed
        if mode == Mode.TAKEOFF and (previous != Mode.TAKEOFF or idle):
            refused = self._start_takeoff(self.flight.takeoff_alt_m)
            if refused:
                return MAV_RESULT_DENIED, refused
        elif mode == Mode.RTL and (previous != Mode.RTL or idle):
            refused = self._start_rtl()
            if refused:
                return MAV_RESULT_DENIED, refused
        self.mode = mode
        if mode != Mode.LAND and not (mode == Mode.RTL and previous == Mode.RTL):
            self.touchdown = None  # RTL touches down only at the end of its own plan
            self.land = None
        if mode not in (Mode.TAKEOFF, Mode.RTL):
            self.auto = None
        if mode in (Mode.TAKEOFF, Mode.RTL, Mode.POSCTL):
            self.mission_running = False
        if mode == Mode.POSCTL and previous != Mode.POSCTL:
            self.manual_sp = None
        if mode == Mode.HOLD:
            self.hold = self._current_pose_ref()
            self.mission_running = False
        elif mode == Mode.MISSION and (previous != Mode.MISSION or not self.mission_running):
            self._start_mission()
        elif mode == Mode.LAND and previous != Mode.LAND:
            self._start_landing()
        elif mode == Mode.OFFBOARD:
            self.mission_running = False
            if previous != Mode.OFFBOARD:
                self.offboard_sp = None  # the approach starts from the reference flown
        self._maybe_start_flight()
        if previous != mode:
            self.say(SEVERITY_INFO, f"mode {mode.name}")
        return MAV_RESULT_ACCEPTED, f"mode {mode.name}"

    def takeoff(self, target_up_m: float | None = None) -> tuple[int, str]:
        """MAV_CMD_NAV_TAKEOFF: TAKEOFF, climbing straight up to `target_up_m` above home
        (None: MIS_TAKEOFF_ALT above where the vehicle should be), then HOLD. As PX4 does, a
        target less than MIS_TAKEOFF_ALT above the vehicle is raised to that, with a
        warning."""
        if not self.armed:
            return MAV_RESULT_DENIED, "takeoff: not armed"
        climb = self.flight.takeoff_alt_m
        if target_up_m is not None:
            wanted = target_up_m - self._current_pose_ref().p_enu_m[2]
            if not math.isfinite(wanted):
                return MAV_RESULT_DENIED, "takeoff: altitude not finite"
            if wanted < climb:
                self.say(SEVERITY_WARNING, f"takeoff: using the minimum climb {climb:.1f} m")
            climb = max(climb, wanted)
        refused = self._start_takeoff(climb)
        if refused:
            return MAV_RESULT_DENIED, refused
        previous = self.mode
        self.mode = Mode.TAKEOFF
        self.touchdown = None
        self.land = None
        self.mission_running = False
        self._maybe_start_flight()
        if previous != Mode.TAKEOFF:
            self.say(SEVERITY_INFO, f"mode {Mode.TAKEOFF.name}")
        return MAV_RESULT_ACCEPTED, f"takeoff: climbing {climb:.1f} m"

    def _start_takeoff(self, climb_m: float) -> str:
        """Plan TAKEOFF's climb (one NAV_TAKEOFF item); a reason if refused, else ""."""
        start = self._current_pose_ref()
        z_ned = -(start.p_enu_m[2] + climb_m)
        x, y = start.p_enu_m[1], start.p_enu_m[0]
        if norm3((x, y, z_ned)) > self.limits.max_distance_m:
            return "takeoff: beyond GF_MAX_DIST"
        item = MissionItem(0, MAV_FRAME_LOCAL_NED, MAV_CMD_NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0,
                           math.nan, 0, 0, z_ned)
        self.auto = MissionExecutor((item,), self.limits)
        self.auto.start(self.clock_us * 1e-6, start.p_enu_m, start.q_enu_flu)
        return ""

    def _start_rtl(self) -> str:
        """Plan RTL (module docstring): climb to RTL_RETURN_ALT if lower, travel home at
        MPC_XY_CRUISE, land; a reason if refused, else ""."""
        start = self._current_pose_ref()
        z_ned = min(-start.p_enu_m[2], -self.flight.rtl_return_alt_m)
        if abs(z_ned) > self.limits.max_distance_m:
            return "RTL: return altitude beyond GF_MAX_DIST"
        items = (
            MissionItem(0, MAV_FRAME_LOCAL_NED, MAV_CMD_NAV_TAKEOFF, 1, 1, 0.0, 0.0, 0.0,
                        math.nan, 0, 0, z_ned),
            MissionItem(1, MAV_FRAME_LOCAL_NED, MAV_CMD_NAV_WAYPOINT, 0, 1, 0.0, 0.0, 0.0,
                        math.nan, 0, 0, z_ned),
            MissionItem(2, MAV_FRAME_LOCAL_NED, MAV_CMD_NAV_LAND, 0, 1, 0.0, 0.0, 0.0,
                        math.nan, 0, 0, 0.0))
        limits = replace(self.limits, cruise_speed_m_s=self.flight.rtl_cruise_m_s)
        self.auto = MissionExecutor(items, limits)
        self.auto.start(self.clock_us * 1e-6, start.p_enu_m, start.q_enu_flu)
        self.say(SEVERITY_INFO, f"RTL: return at {-z_ned:.1f} m, then land")
        return ""

    def mission_start(self, first: int = 0) -> tuple[int, str]:
        if not self.mission:
            return MAV_RESULT_DENIED, "no mission"
        if not 0 <= first < len(self.mission):
            return MAV_RESULT_DENIED, f"no mission item {first}"
        self.mission_current = first
        self.mission_done = False
        self.mission_running = False
        self.mode = Mode.MISSION
        self.touchdown = None
        self.land = None
        self.auto = None
        self._start_mission()
        self._maybe_start_flight()
        self.say(SEVERITY_INFO, "mission started")
        return MAV_RESULT_ACCEPTED, "mission started"

    def set_mission(self, items: tuple[MissionItem, ...]) -> None:
        """A new mission (already validated by the mission protocol)."""
        self.mission = tuple(items)
        self.mission_current = 0
        self.mission_done = False
        self.executor = None
        if self.mode == Mode.MISSION:
            self.mode = Mode.HOLD
            self.hold = self._current_pose_ref()
            self.mission_running = False
            self.say(SEVERITY_INFO, "mission replaced: holding")

    def set_mission_current(self, seq: int) -> tuple[int, str]:
        if not 0 <= seq < len(self.mission):
            return MAV_RESULT_DENIED, f"no mission item {seq}"
        self.mission_current = seq
        self.mission_done = False
        if self.mode == Mode.MISSION and self.mission_running:
            self._start_mission()
        return MAV_RESULT_ACCEPTED, f"mission item {seq}"

    def _maybe_start_flight(self) -> None:
        if self.armed and self.mode in (Mode.MISSION, Mode.OFFBOARD, Mode.LAND, Mode.TAKEOFF,
                                        Mode.RTL, Mode.POSCTL):
            self.flight_started = True

    def _start_mission(self) -> None:
        """Plan the mission from the current item, starting now from the desired pose."""
        if not self.armed or not self.mission:
            self.mission_running = False
            return
        start = self._current_pose_ref()
        t_s = self.clock_us * 1e-6
        self.executor = MissionExecutor(self.mission, self.limits)
        self.executor.set_current(self.mission_current, t_s, start.p_enu_m, start.q_enu_flu)
        self.mission_running = True

    def _start_landing(self) -> None:
        start = self._current_pose_ref()
        # NAV_LAND descends vertically from where it starts: x, y are not used.
        land = MissionItem(0, MAV_FRAME_LOCAL_NED, MAV_CMD_NAV_LAND, 1, 1, 0.0, 0.0, 0.0,
                           math.nan, 0, 0, 0.0)
        self.land = MissionExecutor((land,), self.limits)
        self.land.start(self.clock_us * 1e-6, start.p_enu_m, start.q_enu_flu)
        self.touchdown = None

    # ------------------------------------------------------------------ offboard

    def offboard_position(self, now_s: float, frame: int, type_mask: int, p_ned: Vec3,
                          v_ned: Vec3, a_ned: Vec3, yaw: float) -> tuple[bool, str]:
        """SET_POSITION_TARGET_LOCAL_NED (LOCAL_NED only); type_mask bits ignore fields."""
        if frame != MAV_FRAME_LOCAL_NED:
            return False, "position target frame must be LOCAL_NED"
        if not type_mask & 0b111 and not all(math.isfinite(x) for x in p_ned):
            return False, "position target not finite"
        if not type_mask & 0b111 and norm3(p_ned) > self.limits.max_distance_m:
            return False, "position target beyond GF_MAX_DIST"
        for mask, vec, limit, what in ((0b111000, v_ned, MAX_OFFBOARD_SPEED_M_S, "velocity"),
                                       (0b111000000, a_ned, MAX_OFFBOARD_ACC_M_S2,
                                        "acceleration")):
            if not type_mask & mask and all(map(math.isfinite, vec)) and \
                    norm3(vec) > limit:
                return False, f"{what} target above {limit:g}"
        sp = self.offboard
        if not type_mask & 0b111:
            sp.p_enu_m = ned_to_enu(p_ned)
        sp.v_enu_m_s = ned_to_enu(v_ned) if not type_mask & 0b111000 and all(
            map(math.isfinite, v_ned)) else _ZERO
        sp.a_enu_m_s2 = ned_to_enu(a_ned) if not type_mask & 0b111000000 and all(
            map(math.isfinite, a_ned)) else _ZERO
        sp.yaw_ned_rad = yaw if not type_mask & (1 << 10) and math.isfinite(yaw) else None
        sp.received_s = now_s
        sp.seq += 1
        return True, ""

    def offboard_attitude(self, now_s: float, type_mask: int, q_ned_frd: Quat,
                          rates_frd: Vec3) -> tuple[bool, str]:
        """SET_ATTITUDE_TARGET: attitude NED->FRD and body rates; bit 7 ignores attitude."""
        sp = self.offboard
        if not type_mask & (1 << 7):
            n = math.sqrt(sum(c * c for c in q_ned_frd))
            if not math.isfinite(n) or n < 0.5:
                return False, "attitude target not a unit quaternion"
            w, x, y, z = (c / n for c in q_ned_frd)
            sp.q_enu_flu = q_ned_frd_to_enu_flu((w, x, y, z))
        rates_ok = all(math.isfinite(x) for x in rates_frd) and \
            norm3(rates_frd) <= MAX_OFFBOARD_RATE_RAD_S
        sp.omega_flu_rad_s = frd_to_flu(rates_frd) if rates_ok and not type_mask & 0b111 \
            else _ZERO
        sp.received_s = now_s
        sp.seq += 1
        return True, ""

    # ------------------------------------------------------------------ manual control

    def manual_input(self, now_s: float, x: int, y: int, z: int, r: int) -> None:
        """MANUAL_CONTROL (x, y, r -1000..1000; z 0..1000, 500 at the centre)."""
        self.sticks = manual.sticks_from_manual_control(x, y, z, r)
        self.sticks_received_s = now_s

    def manual_fresh(self, now_s: float) -> bool:
        """MANUAL_CONTROL heard within COM_RC_LOSS_T (wall clock)."""
        return now_s - self.sticks_received_s <= self.flight.manual_timeout_s

    def _manual_ref(self, t_us: int) -> Reference:
        sp = self.manual_sp
        if sp is None:
            start = self._current_pose_ref()
            sp = manual.start(t_us, start.p_enu_m, start.q_enu_flu)
            self.manual_limits = lim = manual.fit_envelope(self.flight.sticks,
                                                           self.limits.vehicle,
                                                           start.q_enu_flu)
            if lim.acc_xy_m_s2 < self.flight.sticks.acc_xy_m_s2:  # said, as it is unusual
                self.say(SEVERITY_INFO, f"POSCTL: acc {lim.acc_xy_m_s2:.2g} m/s2, jerk "
                                        f"{lim.jerk_m_s3:.2g} m/s3 here")
        p_vehicle = self.state.p_enu_m if self.state is not None else None
        self.manual_sp, ref = manual.advance(sp, t_us, self.sticks, self.manual_limits,
                                             p_vehicle)
        return ref

    def _offboard_ref(self, t_us: int) -> Reference:
        """The streamed target approached within POSCTL's limits and the vehicle's envelope
        (`fcu.offboard`), from the reference flown when OFFBOARD began (its velocity,
        acceleration and body rate too)."""
        sp = self.offboard_sp
        lim = offboard.limits(self.flight.sticks)
        if sp is None:
            start = self.last_ref if self.armed and self.last_ref is not None \
                else self._current_pose_ref()
            sp = offboard.start(t_us, start, lim, self._envelope())
        self.offboard_sp, ref = offboard.advance(sp, t_us, self.offboard.target(), lim,
                                                 self._envelope())
        refused = self.offboard_sp.refused
        if refused and refused != self._offboard_refused:
            self.say(SEVERITY_WARNING, refused)
        self._offboard_refused = refused
        return ref

    def _envelope(self) -> Envelope | None:
        vehicle = self.limits.vehicle
        return envelope(vehicle) if vehicle is not None else None

    # ------------------------------------------------------------------ failsafe reactions

    @property
    def landing(self) -> bool:
        """Landing or returning: LAND or RTL mode, a touchdown, or a mission flying its
        NAV_LAND item (a GCS link loss does not interrupt these)."""
        if self.mode in (Mode.LAND, Mode.RTL) or self.touchdown is not None:
            return True
        return self.mode == Mode.MISSION and self.mission_running and \
            0 <= self.mission_current < len(self.mission) and \
            self.mission[self.mission_current].command == MAV_CMD_NAV_LAND

    def failsafe_hold(self, reason: str) -> None:
        """A failsafe reaction: stop where the vehicle should be and hold."""
        self.mode = Mode.HOLD
        self.hold = self._current_pose_ref()
        self.mission_running = False
        self.touchdown = None
        self.land = None
        self.auto = None
        self.say(SEVERITY_CRITICAL, reason, FAILSAFE)

    def failsafe_land(self, reason: str) -> None:
        if self.mode != Mode.LAND:
            self.mode = Mode.LAND
            self.auto = None
            self._start_landing()
        self.say(SEVERITY_CRITICAL, reason, FAILSAFE)

    # ------------------------------------------------------------------ references

    def reference(self, t_us: int) -> Reference:
        """The desired pose, twist and acceleration at t_us (flight clock)."""
        self.clock_us = t_us
        t_s = t_us * 1e-6
        if self.touchdown is not None:
            return self._touchdown_ref(t_us)
        if self.mode == Mode.MISSION and self.mission_running and self.executor is not None:
            return self._mission_ref(t_s)
        if self.mode == Mode.OFFBOARD:
            return self._offboard_ref(t_us)
        if self.mode == Mode.LAND and self.land is not None:
            self.land.update(t_s)
            ref = self.land.sample(t_s)
            if self.land.completed:
                self._begin_touchdown(t_us, ref)
            return ref
        if self.mode in (Mode.TAKEOFF, Mode.RTL) and self.auto is not None:
            return self._auto_ref(t_us)
        if self.mode == Mode.POSCTL:
            return self._manual_ref(t_us)
        return self._hold_ref(t_us)

    def _hold_ref(self, t_us: int) -> Reference:
        """HOLD: a reference that was moving brakes within OFFBOARD's limits to where it
        comes to rest, and `hold` becomes that pose (PX4's and ArduPilot's hold); one at
        rest is held as it is. A new `hold` (a mode change, a failsafe) brakes afresh."""
        if self.hold is None:
            self.hold = self._current_pose_ref()
        if self._hold_shaped is not self.hold:
            start = self.last_ref if self.armed and self.last_ref is not None else self.hold
            self.hold_sp, self.hold = offboard.brake(t_us, start,
                                                     offboard.limits(self.flight.sticks),
                                                     self._envelope())
            self._hold_shaped = self.hold
        assert self.hold_sp is not None
        if offboard.settled(self.hold_sp):
            return self.hold
        self.hold_sp, ref = offboard.advance(self.hold_sp, t_us, None,
                                             offboard.limits(self.flight.sticks))
        return ref

    def _mission_ref(self, t_s: float) -> Reference:
        executor = self.executor
        assert executor is not None
        events = executor.update(t_s)
        self.mission_events.extend(events)
        for ev in events:
            if ev.kind == "current":
                self.mission_current = ev.seq
        ref = executor.sample(t_s)
        if executor.completed:
            self.mission_running = False
            self.mission_done = True
            self.say(SEVERITY_INFO, "mission complete")
            last = self.mission[-1].command if self.mission else None
            if last == MAV_CMD_NAV_LAND:
                self._begin_touchdown(round(t_s * 1e6), ref)
            else:
                self.mode = Mode.HOLD
                self.hold = pose_ref(ref.p_enu_m, ref.q_enu_flu)
        return ref

    def _auto_ref(self, t_us: int) -> Reference:
        """TAKEOFF's or RTL's plan; at its end TAKEOFF holds, RTL touches down."""
        auto = self.auto
        assert auto is not None
        t_s = t_us * 1e-6
        auto.update(t_s)
        ref = auto.sample(t_s)
        if auto.completed:
            self.auto = None
            if self.mode == Mode.RTL:
                self._begin_touchdown(t_us, ref)
            else:
                self.mode = Mode.HOLD
                self.hold = pose_ref(ref.p_enu_m, ref.q_enu_flu)
                self.say(SEVERITY_INFO, "takeoff complete: mode HOLD")
        return ref

    def _begin_touchdown(self, t_us: int, ref: Reference) -> None:
        self.touchdown = Touchdown(t_us, ref.p_enu_m, ref.q_enu_flu)
        self.still_since_us = None
        self.on_ground = False  # from here on only the land detector's evidence counts

    def _touchdown_ref(self, t_us: int) -> Reference:
        td = self.touchdown
        assert td is not None
        speed = self.limits.land_speed_m_s
        depth = speed * (t_us - td.t_us) * 1e-6
        v = (0.0, 0.0, -speed)
        if depth >= TOUCHDOWN_DEPTH_M:
            depth, v = TOUCHDOWN_DEPTH_M, _ZERO
        x, y, z = td.p_enu_m
        return Reference((x, y, z - depth), td.q_enu_flu, v, _ZERO, _ZERO, _ZERO)

    def land_detector(self, t_us: int, lift_n: float, weight_n: float) -> bool:
        """During a touchdown: True once the vehicle is on the ground (then disarm).

        As PX4's land detector: on the ground = still (speed below LANDED_SPEED_M_S), held up
        (at the ground plane's height, or the set-point more than TOUCHDOWN_BLOCKED_M below
        the vehicle) and with little lift
        (the commanded force along the world's up below LANDED_LIFT_RATIO of the weight:
        something else carries the rest), for LANDED_STILL_S. A vehicle still in the air
        needs its whole weight in lift."""
        if self.touchdown is None or self.state is None:
            return False
        s = self.state
        speed = math.sqrt(sum(v * v for v in s.v_flu_m_s))
        ref = self.last_ref
        blocked = s.p_enu_m[2] < LANDED_ALTITUDE_M or (
            ref is not None and s.p_enu_m[2] - ref.p_enu_m[2] > TOUCHDOWN_BLOCKED_M)
        if speed >= LANDED_SPEED_M_S or not blocked or lift_n > LANDED_LIFT_RATIO * weight_n:
            self.still_since_us = None
        elif self.still_since_us is None:
            self.still_since_us = t_us
        if self.still_since_us is not None and \
                (t_us - self.still_since_us) * 1e-6 >= LANDED_STILL_S:
            self.on_ground = True
        return self.on_ground
