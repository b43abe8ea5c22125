"""The commander's state and the reference each mode flies at each step (mission, offboard,
hold, land and its touchdown, takeoff and return, position control), on the flight clock;
pure, no I/O, no MAVLink. `fcu.modes.commander` changes the modes; this module flies them.

OFFBOARD flies the streamed targets (`fcu.modes.offboard_stream`) through the approach shaper
(`fcu.modes.offboard`), HOLD brakes with the same shaper to where the reference comes to rest,
POSCTL moves the set-point as the sticks say (`fcu.modes.manual`), MISSION, TAKEOFF, RTL and LAND
sample their mission executors, and a landing ends in the touchdown and the land detector
(`fcu.modes.landing`). The offboard and manual streams' freshness is judged on the wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from common.outcome import INFO, Event
from common.wire.mav_enums import MAV_CMD, MAV_SEVERITY
from common.wire.mission_items import MissionItem
from common.wire.modes import Mode
from fcu.control.dualquat import Q_IDENTITY, Vec3
from fcu.control.tracker import Reference, VehicleState, pose_ref
from fcu.envelope.feasibility import Envelope, envelope
from fcu.mission.executor import MissionEvent, MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.start import MissionPlan, PosctlFit
from fcu.modes import manual, offboard
from fcu.modes.landing import (
    LANDED_STILL_S,
    Touchdown,
    held_up_and_still,
    landed_state,
    touchdown_ref,
)
from fcu.modes.manual import ManualSetpoint, Sticks, StickSettings
from fcu.modes.offboard_stream import AttitudeTarget, OffboardSetpoint, PositionTarget
from fcu.reference import approach
from fcu.work import InlineWork, Outcome, Work

_ZERO: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class FlightSettings:
    """The automatic modes' and POSCTL's parameters (PX4's names)."""

    takeoff_alt_m: float = 2.5  # MIS_TAKEOFF_ALT: TAKEOFF climbs this much
    rtl_return_alt_m: float = 10.0  # RTL_RETURN_ALT: RTL climbs to this height above home
    rtl_cruise_m_s: float = 5.0  # MPC_XY_CRUISE: RTL's travel speed
    manual_timeout_s: float = 0.5  # COM_RC_LOSS_T: POSCTL without MANUAL_CONTROL -> HOLD
    sticks: StickSettings = field(default_factory=StickSettings)


ANCHOR_LEAD_US = 10_000  # beside the loop: a plan is made this far ahead, at least
LEAD_MAX_US = 100_000  # and at most this far, after plans that came late (`_on_time`)
COAST_MAX_US = 250_000  # a coast whose plan is not in by then is planned in the loop (late work)


class _Ahead:
    """A plan under way beside the loop, asked at `t_us` (flight clock)."""

    __slots__ = ("t_us",)

    def __init__(self, t_us: int) -> None:
        self.t_us = t_us


class ModeReferences:
    """The commander's state, and the reference of the mode in force (`reference`)."""

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
        self.mission_offset_s = 0.0  # the executor's timeline: the flight clock minus this
        self.mission_plan: MissionPlan | None = None  # a mission's start under way
        self.posctl_fit: PosctlFit | None = None  # POSCTL's limits being fitted
        self.work: Work = InlineWork()  # where plans are made (`fcu.work`; the FCU's own)
        self.mission_running = False
        self.mission_done = False
        self.hold: Reference | None = None
        self.land: MissionExecutor | None = None
        self.auto: MissionExecutor | None = None  # TAKEOFF's or RTL's plan
        self.touchdown: Touchdown | None = None
        self.touchdown_speed_cap_m_s = math.inf  # set from the gains (`fcu.pipeline`)
        self.offboard = OffboardSetpoint()
        self.sticks = manual.CENTRED  # the latest MANUAL_CONTROL
        self.sticks_received_s = -math.inf  # wall clock; -inf: never
        self.manual_sp: ManualSetpoint | None = None  # POSCTL's set-point (None: from here)
        self.manual_limits: StickSettings = self.flight.sticks  # fitted to the vehicle
        self.offboard_sp: offboard.Shaped | None = None  # OFFBOARD's shaper (None: from here)
        self._anchoring: _Ahead | None = None  # a new sample's anchor under way beside
        self._anchored: offboard.Shaped | None = None  # taken in, flown from its time
        self.late_anchors = 0  # anchors that came after their time (planned again)
        self._offboard_refused = ""  # the last refusal said
        # HOLD brakes to `hold` (where the reference stops) with the same shaper
        self.hold_sp: offboard.Shaped | None = None
        self._hold_shaped: Reference | None = None  # the hold that hold_sp brakes to
        self._braking: _Ahead | None = None  # HOLD's brake under way beside the loop
        self._braked: tuple[offboard.Shaped, Reference] | None = None  # taken in, not flown
        self.inline_plans = 0  # coasts planned in the loop: their work came too late
        self.lead_us = ANCHOR_LEAD_US  # how far ahead plans beside the loop are made
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
        if self.state is not None:
            self.on_ground = landed_state(self.armed, self.on_ground, self.state)

    def _current_pose_ref(self) -> Reference:
        """Where the vehicle should be now: the last desired pose in flight, else the state."""
        if self.armed and self.last_ref is not None:
            return pose_ref(self.last_ref.p_enu_m, self.last_ref.q_enu_flu)
        if self.state is None:
            return pose_ref(_ZERO, Q_IDENTITY)
        return pose_ref(self.state.p_enu_m, self.state.q_enu_flu)

    # ------------------------------------------------------------------ streamed targets

    def offboard_position(self, now_s: float, target: PositionTarget) -> tuple[bool, str]:
        """A position target (SET_POSITION_TARGET_LOCAL_NED, decoded by `fcu.edge.setpoint_wire`)
        received at `now_s` (wall clock); (kept, why not)."""
        refused = self.offboard.take_position(now_s, target, self.limits.max_distance_m)
        return not refused, refused

    def offboard_attitude(self, now_s: float, target: AttitudeTarget) -> tuple[bool, str]:
        """An attitude target (SET_ATTITUDE_TARGET, decoded by `fcu.edge.setpoint_wire`)
        received at `now_s` (wall clock); (kept, why not)."""
        refused = self.offboard.take_attitude(now_s, target)
        return not refused, refused

    def manual_input(self, now_s: float, sticks: Sticks) -> None:
        """The sticks of a MANUAL_CONTROL received at `now_s` (wall clock), as deflections
        (decoded by `fcu.edge.setpoint_wire.sticks_from_manual_control`)."""
        self.sticks = sticks
        self.sticks_received_s = now_s

    def manual_fresh(self, now_s: float) -> bool:
        """MANUAL_CONTROL heard within COM_RC_LOSS_T (wall clock)."""
        return now_s - self.sticks_received_s <= self.flight.manual_timeout_s

    def _manual_ref(self, t_us: int) -> Reference:
        sp = self.manual_sp
        if sp is None:
            start = self._current_pose_ref()
            if self.posctl_fit is not None:  # its limits being fitted: hold still till then
                return start
            sp = manual.start(t_us, start.p_enu_m, start.q_enu_flu)
        p_vehicle = self.state.p_enu_m if self.state is not None else None
        self.manual_sp, ref = manual.advance(sp, t_us, self.sticks, self.manual_limits,
                                             p_vehicle)
        return ref

    def _offboard_ref(self, t_us: int) -> Reference:
        """The streamed target approached within POSCTL's limits and the vehicle's envelope
        (`fcu.modes.offboard`), from the reference flown when OFFBOARD began (its velocity,
        acceleration and body rate too). Where the work runs beside the loop a new sample
        is anchored there (`_anchor_beside`), not in this step."""
        sp = self.offboard_sp
        lim = offboard.limits(self.flight.sticks)
        if sp is None:
            start = self.last_ref if self.armed and self.last_ref is not None \
                else self._current_pose_ref()
            self._anchoring = self._anchored = None
            if self.work.immediate or not offboard.moving(start):
                sp = offboard.start(t_us, start, lim, self._envelope())
            else:  # planned beside (`_anchor_beside`): the reference coasts meanwhile
                sp = offboard.coast(t_us, start)
        if self.work.immediate:
            self.offboard_sp, ref = offboard.advance(sp, t_us, self.offboard.target(), lim,
                                                     self._envelope())
        else:
            self.offboard_sp, ref = self._anchor_beside(sp, t_us, lim)
        refused = self.offboard_sp.refused
        if refused and refused != self._offboard_refused:
            self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, refused)
        self._offboard_refused = refused
        return ref

    def _anchor_beside(self, sp: offboard.Shaped, t_us: int,
                       lim: StickSettings) -> tuple[offboard.Shaped, Reference]:
        """The plan in force flown on; a new sample anchored by `work` at ANCHOR_LEAD_US
        ahead, from the reference this plan gives there (`offboard.advance` to that time:
        continuous), and flown from then on; with no new sample, a coast (OFFBOARD entered
        moving) is given its start there (`offboard.start_ahead`). An anchor that came too
        late is planned again further ahead; one at a time (the newest sample when the last
        is in); a coast still unplanned after COAST_MAX_US is planned in this step."""
        anchored = self._anchored
        if anchored is not None and t_us >= anchored.t_us:
            sp, self._anchored = anchored, None
        target = self.offboard.target()
        if self._coasted_too_long(sp, t_us):
            self._anchoring = self._anchored = None
            return offboard.start_ahead(sp, t_us, lim, self._envelope())
        sp, ref = offboard.advance(sp, t_us, None, lim)
        if self._anchoring is not None or self._anchored is not None:
            return sp, ref
        job = _Ahead(t_us)
        if target is not None and target.seq != sp.seq:
            self._anchoring = job
            self.work.submit(offboard.advance, (sp, t_us + self.lead_us, target, lim,
                                                self._envelope()),
                             lambda outcome: self._anchored_in(job, outcome))
        elif sp.seq == offboard.COAST:
            self._anchoring = job
            self.work.submit(offboard.start_ahead, (sp, t_us + self.lead_us, lim,
                                                    self._envelope()),
                             lambda outcome: self._anchored_in(job, outcome))
        return sp, ref

    def _coasted_too_long(self, sp: offboard.Shaped, t_us: int) -> bool:
        """A coast whose plan has not come within COAST_MAX_US (the work is late or failed):
        it is planned in the loop, counted in `inline_plans` and said."""
        if sp.seq != offboard.COAST or t_us - sp.anchor_us < COAST_MAX_US:
            return False
        self.inline_plans += 1
        self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, "work late: planned in the loop")
        return True

    def _anchored_in(self, job: _Ahead,
                     outcome: Outcome[tuple[offboard.Shaped, Reference]]) -> None:
        if job is not self._anchoring or self.mode != Mode.OFFBOARD:
            return  # OFFBOARD left (or entered again) meanwhile
        self._anchoring = None
        if outcome.value is None:
            self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, f"offboard: {outcome.error}")
            return
        shaped = outcome.value[0]
        if self._on_time(job, shaped.t_us):  # else planned again from the next step
            self._anchored = shaped

    def _on_time(self, job: _Ahead, planned_for_us: int) -> bool:
        """Whether a plan made beside for `planned_for_us` came before that time (a late one
        would jump: it is counted and planned again). The lead adapts to the work: after a
        late plan it is twice what that one took (up to LEAD_MAX_US); each plan on time
        brings it a quarter of the way back to ANCHOR_LEAD_US."""
        if planned_for_us > self.clock_us:
            self.lead_us -= (self.lead_us - ANCHOR_LEAD_US) // 4
            return True
        self.late_anchors += 1
        self.lead_us = min(LEAD_MAX_US, max(self.lead_us, 2 * (self.clock_us - job.t_us)))
        return False

    def _envelope(self) -> Envelope | None:
        vehicle = self.limits.vehicle
        return envelope(vehicle) if vehicle is not None else None

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
        rest is held as it is. A new `hold` (a mode change, a failsafe) brakes afresh.
        Where the work runs beside the loop the brake is planned there (`_brake_beside`)
        and the reference coasts until it is in."""
        lim = offboard.limits(self.flight.sticks)
        if self.hold is None:
            self.hold = self._current_pose_ref()
        if self._hold_shaped is not self.hold:
            start = self.last_ref if self.armed and self.last_ref is not None else self.hold
            self._braking = self._braked = None
            if self.work.immediate or not offboard.moving(start):
                self.hold_sp, self.hold = offboard.brake(t_us, start, lim, self._envelope())
            else:
                self.hold_sp = offboard.coast(t_us, start)
            self._hold_shaped = self.hold
        assert self.hold_sp is not None
        if self.hold_sp.seq == offboard.COAST:
            self._brake_beside(t_us, lim)
        if offboard.settled(self.hold_sp):
            return self.hold
        self.hold_sp, ref = offboard.advance(self.hold_sp, t_us, None, lim)
        return ref

    def _brake_beside(self, t_us: int, lim: StickSettings) -> None:
        """While HOLD coasts: its brake planned by `work` at ANCHOR_LEAD_US ahead from where
        the coast is then (`offboard.brake_ahead`), taken in at its time; one that came too
        late is planned again; after COAST_MAX_US it is planned in this step."""
        sp = self.hold_sp
        assert sp is not None
        braked = self._braked
        if braked is not None and t_us >= braked[0].t_us:
            self._braked = None
            self.hold_sp, self.hold = braked
        elif self._coasted_too_long(sp, t_us):
            self._braking = self._braked = None
            self.hold_sp, self.hold = offboard.brake_ahead(sp, t_us, lim, self._envelope())
        elif self._braking is None and braked is None:
            job = self._braking = _Ahead(t_us)
            self.work.submit(offboard.brake_ahead, (sp, t_us + self.lead_us, lim,
                                                    self._envelope()),
                             lambda outcome: self._braked_in(job, outcome))
            return
        else:
            return
        self._hold_shaped = self.hold

    def _braked_in(self, job: _Ahead,
                   outcome: Outcome[tuple[offboard.Shaped, Reference]]) -> None:
        if job is not self._braking:
            return  # a newer hold asked meanwhile
        self._braking = None
        if outcome.value is None:
            self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, f"hold: {outcome.error}")
        elif self._on_time(job, outcome.value[0].t_us):  # else planned again
            self._braked = outcome.value

    def _mission_ref(self, t_flight_s: float) -> Reference:
        executor = self.executor
        assert executor is not None
        t_s = t_flight_s - self.mission_offset_s  # on the plan's timeline
        events = executor.update(t_s)
        self.mission_events.extend(events)
        for ev in events:
            if ev.kind == "current":
                self.mission_current = ev.seq
        ref = executor.sample(t_s)
        if executor.completed:
            self.mission_running = False
            self.mission_done = True
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "mission complete")
            last = self.mission[-1].command if self.mission else None
            if last == MAV_CMD.MAV_CMD_NAV_LAND:
                self._begin_touchdown(round(t_flight_s * 1e6), ref)
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
                self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "takeoff complete: mode HOLD")
        return ref

    def _begin_touchdown(self, t_us: int, ref: Reference) -> None:
        self.touchdown = Touchdown(t_us, ref.p_enu_m, ref.q_enu_flu)
        self.still_since_us = None
        self.on_ground = False  # from here on only the land detector's evidence counts
        self.say_touchdown_cap()

    def say_touchdown_cap(self) -> None:
        """An INFO when MIS_LAND_SPD is faster than the touchdown the gains land at: faster,
        the position loop's damping would push the rotors' thrust to reverse on the ground
        (`fcu.modes.landing.touchdown_speed_cap`)."""
        if self.touchdown_speed_m_s < self.limits.land_speed_m_s:
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO,
                     f"touchdown capped at {self.touchdown_speed_m_s:.2f} m/s (MIS_LAND_SPD "
                     f"{self.limits.land_speed_m_s:.2f})")

    @property
    def touchdown_speed_m_s(self) -> float:
        """The land speed (MIS_LAND_SPD), capped by what the gains land at
        (`fcu.modes.landing.touchdown_speed_cap`)."""
        return min(self.limits.land_speed_m_s, self.touchdown_speed_cap_m_s)

    def _touchdown_ref(self, t_us: int) -> Reference:
        assert self.touchdown is not None
        z = self.state.p_enu_m[2] if self.state is not None else None
        return touchdown_ref(self.touchdown, t_us, self.touchdown_speed_m_s, z)

    def land_detector(self, t_us: int, lift_n: float, weight_n: float) -> bool:
        """During a touchdown: True once the vehicle is on the ground (then disarm): held up
        and still for LANDED_STILL_S (`held_up_and_still`)."""
        if self.touchdown is None or self.state is None:
            return False
        if not held_up_and_still(self.state, self.last_ref, lift_n, weight_n):
            self.still_since_us = None
        elif self.still_since_us is None:
            self.still_since_us = t_us
        if self.still_since_us is not None and \
                (t_us - self.still_since_us) * 1e-6 >= LANDED_STILL_S:
            self.on_ground = True
        return self.on_ground
