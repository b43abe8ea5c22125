"""The mode in force and each mode's state, the one table of what entering a mode resets
(`ModeState.switch`), and the reference each mode flies at each step; pure, no I/O.

Each mode's state is a part with the behaviour that belongs to it: the mission's
(`fcu.modes.mission_run`), OFFBOARD's shaper and HOLD's brake with the plans they make
beside the loop (`fcu.modes.shaping`), POSCTL's (`fcu.modes.posctl`), the landing's
(`fcu.modes.landing.Descent`), and TAKEOFF's or RTL's plan (`auto`, missions of
`fcu.modes.auto_plans` items). What the commander knows of the vehicle (arming, the state,
the reference flown, the parameters, where work runs) is read through `Known`.

Every mode change goes through `switch` (a mode command, TAKEOFF, a mission's start or
refusal, a replaced mission, the end of TAKEOFF or of a mission, a failsafe). Entering a
mode resets its own state, except when it is re-entered (HOLD's always):

| entered  | its own state                                | also left standing            |
|----------|----------------------------------------------|-------------------------------|
| HOLD     | holds where the vehicle should be (always)   | -                             |
| MISSION  | the mission's run stops unless re-entered    | -                             |
| OFFBOARD | the shaper starts again from the reference flown | -                         |
| POSCTL   | the set-point starts again from here         | -                             |
| LAND     | the descent is planned from here             | the mission's run (ACTIVE)    |
| TAKEOFF  | its climb (planned first: `plan_auto`)       | its plan                      |
| RTL      | its return (planned first: `plan_auto`)      | its plan; re-entered, its touchdown |

and what belongs to the other modes ends: the landing (LAND's plan, a touchdown), TAKEOFF's
or RTL's plan, the mission's run. A mission replaced during its own touchdown lets that
touchdown go on (`touchdown_goes_on`). Arming and disarming keep the mode and reset here too
(`on_arming`: HOLD, POSCTL and OFFBOARD start from where the vehicle is; `on_disarming`).

LAND's, TAKEOFF's and RTL's plans start at rest, and so does a mission's. Asked while the
reference flown still moves, they start where HOLD's brake brings it to rest, when it does
(`_after_brake`; a mission's plan is made from there: `brake_then`), as PX4's land and
return slow down first: started at once, the reference's velocity stepped to zero, and
LAND entered at 7 m/s left the rotors saturated for 3 s and the vehicle 7.5 m off its
reference.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

from common.wire.mav_enums import MAV_SEVERITY
from common.wire.mission_items import MissionItem
from common.wire.modes import Mode
from fcu.control.dualquat import Q_IDENTITY, Vec3
from fcu.envelope.feasibility import Envelope, envelope
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.modes import auto_plans, offboard
from fcu.modes.landing import Descent
from fcu.modes.mission_run import MissionRun
from fcu.modes.offboard_stream import OffboardSetpoint
from fcu.modes.posctl import Posctl
from fcu.modes.settings import FlightSettings
from fcu.modes.shaping import HoldBrake, OffboardShaper, PlansAhead
from fcu.modes.voice import Voice
from fcu.stages import Reference, VehicleState, pose_ref
from fcu.work import Work

_ZERO: Vec3 = (0.0, 0.0, 0.0)


class Known(Protocol):
    """What the commander knows of the vehicle, as the modes read it."""

    armed: bool
    state: VehicleState | None
    last_ref: Reference | None  # the reference flown at the latest step
    limits: MissionLimits
    flight: FlightSettings
    work: Work  # where plans are made (`fcu.work`)
    voice: Voice
    offboard: OffboardSetpoint  # OFFBOARD's stream: the latest sample


class ModeState:
    """The mode in force, each mode's state, and the reference it flies (`reference`)."""

    def __init__(self, known: Known) -> None:
        self.known = known
        self.mode = Mode.HOLD
        self.auto: MissionExecutor | None = None  # TAKEOFF's or RTL's plan
        self.mission_run = MissionRun()
        self.descent = Descent()
        self.posctl = Posctl(known.flight.sticks)
        self.ahead = PlansAhead(known.voice)
        self.shaper = OffboardShaper(self.ahead, lambda: self.mode == Mode.OFFBOARD)
        self.brake = HoldBrake(self.ahead)
        self._rest_since_us: int | None = None  # the reference at rest for a mission's start
        # LAND's, TAKEOFF's or RTL's plan, started (at t_us, from a pose) when HOLD's brake
        # has brought the moving reference to rest: `_after_brake`
        self.lead_in: Callable[[int, Reference], None] | None = None
        # a mission's start, made (at t_us, from a pose) when HOLD's brake has brought the
        # moving reference to rest: `brake_then`
        self.plan_lead_in: Callable[[int, Reference], None] | None = None

    # ------------------------------------------------------------------ entering a mode

    def switch(self, mode: Mode, previous: Mode | None = None, hold: Reference | None = None,
               touchdown_goes_on: bool = False) -> None:
        """Enter `mode` from `previous` (the mode in force unless given): the one place a
        mode change resets state (the module docstring's table). HOLD holds at `hold`
        (None: where the vehicle should be)."""
        previous = self.mode if previous is None else previous
        again = mode == previous
        self.mode = mode
        if mode not in (Mode.TAKEOFF, Mode.RTL, Mode.LAND):
            self.lead_in = None  # (TAKEOFF's and RTL's are planned before: `plan_auto`)
        self.plan_lead_in = None  # the mode entered flies from the brake's reference
        if not (touchdown_goes_on or mode == Mode.LAND or (again and mode == Mode.RTL)):
            self.descent.end()
        if mode not in (Mode.TAKEOFF, Mode.RTL):
            self.auto = None
        if not (mode == Mode.LAND or (again and mode == Mode.MISSION)):
            self.mission_run.stop()
        if mode == Mode.HOLD:
            self.brake.hold_at(hold if hold is not None else self.here())
        elif again:
            return
        elif mode == Mode.OFFBOARD:
            self.shaper.restart()
        elif mode == Mode.POSCTL:
            self.posctl.restart()
        elif mode == Mode.LAND:
            self._after_brake(lambda t_us, at: self.descent.start(t_us * 1e-6, at,
                                                                  self.known.limits))

    def moving(self) -> bool:
        """The reference flown (in flight) still moves: a plan that starts at rest waits for
        HOLD's brake (`_after_brake`, `brake_then`)."""
        flown = self._flown()
        return flown is not None and offboard.moving(flown)

    def brake_then(self, start: Callable[[int, Reference], None]) -> None:
        """A mission's start asked while the reference moves: HOLD's brake flies until it is
        at rest, then `start(t_us, pose)` plans the mission from there (the mode in force
        stays, as while any mission's plan is made); dropped meanwhile, the mode in force
        flies on from the brake (`_resume_from_brake`)."""
        self.brake.hold_at(self.here())
        self.plan_lead_in = start

    def _after_brake(self, start: Callable[[int, Reference], None]) -> None:
        """`start(t_us, pose)`: a plan that starts at rest, from where the vehicle should be
        now; from a reference flown that still moves, where HOLD's brake brings it to rest,
        when it does (`reference`)."""
        flown = self._flown()
        if flown is None or not offboard.moving(flown):
            self.lead_in = None
            start(self.known.voice.clock_us, self.here())
            return
        self.brake.hold_at(self.here())
        self.lead_in = start

    def on_arming(self) -> None:
        """Armed: the mode in force starts from where the vehicle is (HOLD holds there,
        POSCTL's set-point and OFFBOARD's approach start there: nothing shaped before a
        disarm, possibly in the air, is flown on), with no landing left over. LAND re-armed
        holds where it is; a descent is planned only when LAND is entered from another
        mode."""
        self.brake.hold_at(self.here())
        self.descent.end()
        self.posctl.restart()
        self.shaper.restart()
        self._rest_since_us = None
        self.lead_in = self.plan_lead_in = None

    def start_taken_in(self) -> None:
        """The mission's plan the reference rested for is flown from now (from where it
        rested): nothing to resume."""
        self._rest_since_us = None

    def _resume_from(self, held: Reference, t_us: int, rest_since_us: int) -> None:
        """A mission's start that rested the reference (`reference`) from `rest_since_us`
        ended without its plan flown (dropped, or refused: HOLD): the mode in force flies on
        from the rest, not from the state it had when the start was asked (that would jump
        ahead by as far as it would have flown meanwhile). HOLD holds there; OFFBOARD,
        POSCTL, LAND, a touchdown, TAKEOFF and RTL start again from there; a mission still
        running (its new start dropped) goes on from where it paused, its timeline moved
        by the rest's length."""
        self.shaper.restart()
        self.posctl.restart()
        self.brake.hold_at(held)  # (HOLD entered later holds afresh: `switch`)
        if self.mode == Mode.MISSION and self.mission_run.running:
            self.mission_run.offset_s += (t_us - rest_since_us) * 1e-6
        if self.descent.touchdown is not None:
            self.descent.begin_touchdown(t_us, held)
        elif self.descent.plan is not None:
            self.descent.start(t_us * 1e-6, held, self.known.limits)
        if self.auto is not None and self.lead_in is None:  # TAKEOFF's or RTL's items are
            # absolute: the rest of them (a plan still braking into starts from the rest)
            self.auto.set_current(self.auto.current_seq, t_us * 1e-6, held.p_enu_m,
                                  held.q_enu_flu)

    def on_disarming(self) -> None:
        """Disarmed: what flew ends (the mission's run, the landing, TAKEOFF's or RTL's
        plan); the mode stays."""
        self.mission_run.stop()
        self.descent.end()
        self.auto = None
        self.lead_in = self.plan_lead_in = None

    def plan_auto(self, mode: Mode, previous: Mode) -> str:
        """TAKEOFF's or RTL's plan when entered anew, or again with nothing left to fly
        (e.g. landed, disarmed, re-armed); a reason if refused, else ""."""
        idle = self.auto is None and self.descent.touchdown is None
        if mode == Mode.TAKEOFF and (previous != Mode.TAKEOFF or idle):
            return self.plan_takeoff(self.known.flight.takeoff_alt_m)
        if mode == Mode.RTL and (previous != Mode.RTL or idle):
            return self._plan_rtl()
        return ""

    def plan_takeoff(self, climb_m: float) -> str:
        """Plan TAKEOFF's climb (one NAV_TAKEOFF item); a reason if refused, else "".
        Entered while the reference moves, the climb is checked again where HOLD's brake
        stops: a brake that stops above the target climbs no more (it never comes down to
        it), and one that stops where the target straight above is beyond GF_MAX_DIST
        climbs no more either, and says so (the mode was already accepted: it holds)."""
        start = self.here()
        limits = self.known.limits
        items = auto_plans.takeoff(start.p_enu_m, climb_m, limits.max_distance_m)
        if isinstance(items, str):
            return items
        voice = self.known.voice

        def at_rest(p_enu_m: Vec3) -> tuple[MissionItem, ...]:
            here_z = -p_enu_m[2]  # NED: down
            if here_z <= items[0].z:  # at or above the target: no climb left
                return (items[0]._replace(z=here_z),)
            if isinstance(auto_plans.takeoff_to(p_enu_m, items[0].z, limits.max_distance_m),
                          str):
                voice.say(MAV_SEVERITY.MAV_SEVERITY_WARNING,
                          "takeoff: climb beyond GF_MAX_DIST: holding")
                return (items[0]._replace(z=here_z),)
            return items

        self._fly_auto(items, limits, at_rest)
        return ""

    def _plan_rtl(self) -> str:
        """Plan RTL (`fcu.modes.commander`): climb to RTL_RETURN_ALT if lower, travel home at
        up to MPC_XY_CRUISE, land; a reason if refused, else "". Entered while the reference
        moves, the return altitude is taken again where HOLD's brake stops (a climb at speed
        stops above where RTL came: it returns from there, not down to it first)."""
        start, flight, limits = self.here(), self.known.flight, self.known.limits

        def plan(p_enu_m: Vec3) -> tuple[MissionItem, ...] | str:
            return auto_plans.rtl(p_enu_m, flight.rtl_return_alt_m, limits.max_distance_m)

        items = plan(start.p_enu_m)
        if isinstance(items, str):
            return items
        voice = self.known.voice
        voice.say(MAV_SEVERITY.MAV_SEVERITY_INFO, f"RTL: return at {-items[0].z:.1f} m, then land")

        def at_rest(p_enu_m: Vec3) -> tuple[MissionItem, ...]:
            again = plan(p_enu_m)
            if isinstance(again, str) or again[0].z == items[0].z:
                return items  # the same, or beyond the fence from there: as answered
            voice.say(MAV_SEVERITY.MAV_SEVERITY_INFO, f"RTL: return at {-again[0].z:.1f} m")
            return again

        self._fly_auto(items, replace(limits, cruise_speed_m_s=flight.rtl_cruise_m_s), at_rest)
        return ""

    def _fly_auto(self, items: tuple[MissionItem, ...], limits: MissionLimits,
                  at_rest: Callable[[Vec3], tuple[MissionItem, ...]] | None = None) -> None:
        """Fly `items` from where the vehicle should be, after HOLD's brake if the reference
        moves (`_after_brake`); `at_rest(p)`: the items made again where the brake stops."""
        self.auto = MissionExecutor(items, limits)

        def start(t_us: int, at: Reference) -> None:
            if at_rest is not None:
                again = at_rest(at.p_enu_m)
                if again is not items:
                    self.auto = MissionExecutor(again, limits)
            assert self.auto is not None
            self.auto.start(t_us * 1e-6, at.p_enu_m, at.q_enu_flu)

        self._after_brake(start)

    # ------------------------------------------------------------------ what flies

    @property
    def landing(self) -> bool:
        """Landing or returning: LAND or RTL mode, a touchdown, or a mission flying its
        NAV_LAND item (a GCS link loss does not interrupt these)."""
        if self.mode in (Mode.LAND, Mode.RTL) or self.descent.touchdown is not None:
            return True
        return self.mode == Mode.MISSION and self.mission_run.flying_landing

    def here(self) -> Reference:
        """Where the vehicle should be now: the last desired pose in flight, else the state."""
        known = self.known
        if known.armed and known.last_ref is not None:
            return pose_ref(known.last_ref.p_enu_m, known.last_ref.q_enu_flu)
        if known.state is None:
            return pose_ref(_ZERO, Q_IDENTITY)
        return pose_ref(known.state.p_enu_m, known.state.q_enu_flu)

    def _flown(self) -> Reference | None:
        """The reference flown in flight, else None."""
        return self.known.last_ref if self.known.armed else None

    def _envelope(self) -> Envelope | None:
        vehicle = self.known.limits.vehicle
        return envelope(vehicle) if vehicle is not None else None

    def reference(self, t_us: int) -> Reference:
        """The desired pose, twist and acceleration at t_us (flight clock). While a
        mission's start is under way beside the loop, at rest where its plan starts (where
        the reference was when it was asked), as the loop flies it when the plan is made in
        the step: a mode flown on meanwhile would leave the plan's start behind, and the
        reference would step back to it when the plan is taken in. In lockstep no step sees
        this: the plan is taken in before the next step."""
        self.known.voice.clock_us = t_us
        mode, known = self.mode, self.known
        if (starting := self._mission_start_ref(t_us)) is not None:
            return starting
        if self._rest_since_us is not None:
            self._resume_from(self.here(), t_us, self._rest_since_us)
            self._rest_since_us = None
        if self.lead_in is not None and (braking := self._lead_in(t_us)) is not None:
            return braking
        if self.descent.touchdown is not None:
            return self.descent.touchdown_ref(t_us, known.limits.land_speed_m_s, known.state)
        if mode == Mode.MISSION and self.mission_run.running and \
                self.mission_run.executor is not None:
            return self._mission_ref(t_us * 1e-6)
        if mode == Mode.OFFBOARD:
            return self._offboard_ref(t_us)
        if mode == Mode.LAND and self.descent.plan is not None:
            ref, ended = self.descent.step(t_us)
            if ended:
                self._begin_touchdown(t_us, ref)
            return ref
        if mode in (Mode.TAKEOFF, Mode.RTL) and self.auto is not None:
            return self._auto_ref(t_us)
        if mode == Mode.POSCTL:  # from the reference flown, its velocity kept while it moves
            here = (self._flown() if self.moving() else self.here()) \
                if self.posctl.sp is None else None
            return self.posctl.step(t_us, here,
                                    known.state.p_enu_m if known.state is not None else None)
        return self._hold_ref(t_us)

    def _mission_start_ref(self, t_us: int) -> Reference | None:
        """While a mission's start is under way: HOLD's brake until the reference is at rest
        (`brake_then`), then at rest where its plan starts until it is taken in (at once
        when planned in the loop: then None, the mission flies). None: no start under way
        (one dropped while braking: the mode in force flies on from the brake)."""
        start = self.mission_run.plan
        if start is None or not self.known.armed:
            if self.plan_lead_in is not None:
                self.plan_lead_in = None
                self._resume_from_brake(t_us)
            return None
        if self.plan_lead_in is not None:
            ref = self._hold_ref(t_us)
            if self.brake.sp is None or not offboard.settled(self.brake.sp):
                return ref
            plan_from_here, self.plan_lead_in = self.plan_lead_in, None
            plan_from_here(t_us, ref)
            start = self.mission_run.plan
            if start is None:
                return None  # planned in the loop: taken in (or refused) already
        if self._rest_since_us is None:
            self._rest_since_us = t_us
        return start.start

    def _resume_from_brake(self, t_us: int) -> None:
        """A mission's start dropped while HOLD's brake flew for it (`brake_then`), the mode
        unchanged: OFFBOARD's approach and HOLD's brake start again from the reference
        flown, POSCTL from here; LAND's descent, TAKEOFF's and RTL's plans from where the
        brake brings the reference to rest (`_after_brake`); a touchdown sinks from here; a
        mission still running (its new start dropped) holds, its timeline left behind."""
        self.shaper.restart()
        self.posctl.restart()
        self.brake.hold_at(self.here())
        if self.mode == Mode.MISSION and self.mission_run.running:
            self.switch(Mode.HOLD)
            self.known.voice.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "mission paused: holding")
        if self.descent.touchdown is not None:
            self.descent.begin_touchdown(t_us, self.here())
        elif self.descent.plan is not None and self.lead_in is None:
            descent, limits = self.descent, self.known.limits
            self._after_brake(lambda t, at: descent.start(t * 1e-6, at, limits))
        auto = self.auto
        if auto is not None and self.lead_in is None:
            self._after_brake(lambda t, at: auto.set_current(auto.current_seq, t * 1e-6,
                                                             at.p_enu_m, at.q_enu_flu))

    def _lead_in(self, t_us: int) -> Reference | None:
        """HOLD's brake into LAND's, TAKEOFF's or RTL's plan (`_after_brake`) at t_us; None
        once it has come to rest: the plan is started there, now."""
        ref = self._hold_ref(t_us)
        start = self.lead_in
        assert start is not None
        if self.brake.sp is None or not offboard.settled(self.brake.sp):
            return ref
        self.lead_in = None
        start(t_us, ref)  # at rest where the brake ended: the plan flies on from here
        return None

    def _offboard_ref(self, t_us: int) -> Reference:
        """The streamed target approached from the reference flown when OFFBOARD began."""
        start = None
        if self.shaper.sp is None:
            flown = self._flown()
            start = flown if flown is not None else self.here()
        known = self.known
        return self.shaper.step(t_us, start, known.offboard.target(),
                                offboard.limits(known.flight.sticks), self._envelope(),
                                known.work)

    def _hold_ref(self, t_us: int) -> Reference:
        """HOLD: braking to where the reference comes to rest."""
        if self.brake.hold is None:
            self.brake.hold_at(self.here())
        return self.brake.step(t_us, self._flown(), offboard.limits(self.known.flight.sticks),
                               self._envelope(), self.known.work)

    def _mission_ref(self, t_flight_s: float) -> Reference:
        """The mission's reference; at its end it touches down (a last NAV_LAND) or holds."""
        ref, completed = self.mission_run.step(t_flight_s)
        if completed:
            self.known.voice.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "mission complete")
            if self.mission_run.ends_landing:
                self._begin_touchdown(round(t_flight_s * 1e6), ref)
            else:
                self.switch(Mode.HOLD, hold=pose_ref(ref.p_enu_m, ref.q_enu_flu))
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
                self.switch(Mode.HOLD, hold=pose_ref(ref.p_enu_m, ref.q_enu_flu))
                self.known.voice.say(MAV_SEVERITY.MAV_SEVERITY_INFO,
                                     "takeoff complete: mode HOLD")
        return ref

    def _begin_touchdown(self, t_us: int, ref: Reference) -> None:
        self.descent.begin_touchdown(t_us, ref)
        self.say_touchdown_cap()

    def say_touchdown_cap(self) -> None:
        """An INFO when MIS_LAND_SPD is faster than the touchdown the gains land at: faster,
        the position loop's damping would push the rotors' thrust to reverse on the ground
        (`fcu.modes.landing.touchdown_speed_cap`)."""
        land_speed = self.known.limits.land_speed_m_s
        speed = self.descent.speed_m_s(land_speed)
        if speed < land_speed:
            self.known.voice.say(MAV_SEVERITY.MAV_SEVERITY_INFO,
                                 f"touchdown capped at {speed:.2f} m/s (MIS_LAND_SPD "
                                 f"{land_speed:.2f})")
