"""The commander stage: arming, modes, commands and the reference of the mode in force
(mission, offboard, hold, land, takeoff, return, position control), without I/O.

Time comes in as arguments: `t_us` is the flight clock (simulated in lockstep, monotonic in
real time) for everything that shapes the flight; `now_s` is the wall clock, used only for
the offboard and manual streams' freshness (docs/clocks.md). What the commander says goes
into `events` (on the flight clock, `fcu.modes.voice`); the process shell turns them into
STATUSTEXT.

The mode in force, each mode's state and the one table of what entering a mode resets are
`ModeState` (`fcu.modes.mode_state`, `modes`), which also flies the references; the commander
arms, takes the commands and the failsafes' reactions and changes modes through it.
Arming holds where the vehicle is and restarts POSCTL's set-point; disarming ends the
mission's run, the landing and TAKEOFF's or RTL's plan.

Landing (LAND mode, or a mission whose last item is NAV_LAND): the descent to the ground
plane follows its planned profile; then the set-point sinks and the land detector disarms
(`fcu.modes.landing`): a landing ends on the ground, disarmed, never hovering armed.

TAKEOFF climbs `FlightSettings.takeoff_alt_m` (MIS_TAKEOFF_ALT) straight up from where the
vehicle should be, then holds (HOLD). RTL climbs to `rtl_return_alt_m` (RTL_RETURN_ALT) above
home if it is lower, flies to home's north and east at up to `rtl_cruise_m_s` (MPC_XY_CRUISE)
and lands there as LAND does. Both are planned as missions (NAV_TAKEOFF, NAV_WAYPOINT, NAV_LAND
items: `fcu.modes.auto_plans`) by the mission executor, so their legs are quintic profiles
stretched until the vehicle can fly them (`fcu.mission`, `fcu.envelope.feasibility`). Home is
the origin of the local frame (HOME_POSITION). POSCTL moves the set-point as MANUAL_CONTROL's
sticks say (`fcu.modes.manual`); the stream's freshness is checked on the wall clock like the
offboard one. The FCU's MAVLink edge (`fcu.edge.setpoint_wire`) decodes the offboard and manual
set-points; the commander takes them typed, in ENU/FLU and SI units.

A mission's start (MISSION_START, mode MISSION, a new current item in flight, arming in
MISSION) plans the mission from the desired pose and checks it again: a job for `work`
(`fcu.work`). Where it runs beside the loop the command's answer is IN_PROGRESS
(`MAV_RESULT_IN_PROGRESS`; every command waiting on it is told the final one,
`UnderWay.end`): the reference rests where the plan starts (`ModeState.reference`), the
HEARTBEAT shows the mode in force, until the plan is taken in at a step boundary
(`_planned`); its timeline then starts at that step
(`MissionRun.offset_s`). The same mode asked for again meanwhile waits for the same end; any
other mode change, a disarm, a failsafe or a new mission drops a plan under way.
"""

from __future__ import annotations

import math

from common.outcome import CRASH, FAILSAFE, INFO, Event
from common.wire.mav_enums import MAV_RESULT, MAV_SEVERITY
from common.wire.mission_items import MissionItem
from common.wire.modes import Mode
from fcu.mission.codes import MAV_MISSION_DENIED, result_name
from fcu.mission.executor import MissionEvent, MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.start import MissionPlan, PosctlFit, plan_from
from fcu.modes import manual
from fcu.modes.answer import Answer, Reply
from fcu.modes.manual import Sticks, StickSettings
from fcu.modes.mode_state import ModeState
from fcu.modes.offboard_stream import AttitudeTarget, OffboardSetpoint, PositionTarget
from fcu.modes.settings import FlightSettings
from fcu.modes.voice import Voice
from fcu.reference import approach
from fcu.stages import Reference, VehicleState
from fcu.work import InlineWork, Outcome, Work

IN_PROGRESS = MAV_RESULT.MAV_RESULT_IN_PROGRESS  # answered later, through UnderWay.end
_FLYING = (Mode.MISSION, Mode.OFFBOARD, Mode.LAND, Mode.TAKEOFF, Mode.RTL, Mode.POSCTL)


class Commander:
    """Arming, modes and commands, and the reference of the mode in force (`reference`)."""

    def __init__(self, limits: MissionLimits, offboard_timeout_s: float = 1.0,
                 flight: FlightSettings | None = None) -> None:
        self.limits = limits
        self.offboard_timeout_s = offboard_timeout_s
        self.flight = flight or FlightSettings()
        approach.warm()  # OFFBOARD's and HOLD's planner: compiled before the first period
        self.armed = False
        self.flight_started = False  # lockstep: simulated time runs once this latches
        self.state: VehicleState | None = None
        self.last_ref: Reference | None = None  # the reference flown at the latest step
        self.work: Work = InlineWork()  # where plans are made (`fcu.work`; the FCU's own)
        self.voice = Voice()
        self.offboard = OffboardSetpoint()  # OFFBOARD's stream: the latest sample
        self.modes = ModeState(self)  # the mode in force and each mode's state

    # ------------------------------------------------------------------ what others read

    @property
    def events(self) -> list[Event]:
        return self.voice.events

    @property
    def clock_us(self) -> int:
        """The flight clock at the latest input (events are stamped with it)."""
        return self.voice.clock_us

    @property
    def mission(self) -> tuple[MissionItem, ...]:
        return self.modes.mission_run.items

    @property
    def mission_current(self) -> int:
        return self.modes.mission_run.current

    @property
    def mission_done(self) -> bool:
        return self.modes.mission_run.done

    @property
    def mission_events(self) -> list[MissionEvent]:
        return self.modes.mission_run.events

    @property
    def landed(self) -> bool:
        """On the ground, as the landed state machine last concluded (`Descent`)."""
        return self.modes.descent.on_ground

    @property
    def touchdown_speed_m_s(self) -> float:
        """The land speed (MIS_LAND_SPD), capped by what the gains land at
        (`fcu.modes.landing.touchdown_speed_cap`)."""
        return self.modes.descent.speed_m_s(self.limits.land_speed_m_s)

    @property
    def under_way(self) -> MissionPlan | PosctlFit | None:
        """The mode change whose work runs beside the loop (its waiting commands told the end)."""
        return self.modes.mission_run.plan or self.modes.posctl.fit

    @property
    def mode(self) -> Mode:
        return self.modes.mode

    @property
    def mode_ahead(self) -> Mode:
        """The mode in force once the change under way is made (`mode` when none is): a
        failsafe reacts as it would had the change been made in the loop, at its command."""
        under_way = self.under_way
        return self.mode if under_way is None else under_way.mode

    @property
    def landing_ahead(self) -> bool:
        """`landing`, judged by `mode_ahead`: a change under way (MISSION's start, POSCTL)
        takes the vehicle out of a landing."""
        return self.landing and self.under_way is None

    @property
    def landing(self) -> bool:
        """Landing or returning (`ModeState.landing`): a GCS link loss does not interrupt it."""
        return self.modes.landing

    def say(self, severity: int, text: str, kind: str = INFO) -> None:
        self.voice.say(severity, text, kind)

    # ------------------------------------------------------------------ inputs

    def on_state(self, state: VehicleState, rx_us: int) -> None:
        """A new state, received at `rx_us` (flight clock); the landed state follows it: a
        disarmed vehicle at rest at ground level is on the ground, an armed one comes back
        to it only through `land_detector`, never from its altitude alone (with no ground
        below, Case II, a hover at z = 0 is not a landing)."""
        self.state = state
        self.voice.clock_us = rx_us
        self.modes.descent.update_landed(self.armed, state)

    def drop_state(self) -> None:
        self.state = None  # no state until the next one (the state source changed)

    def step_at(self, t_us: int) -> None:
        """A control period begins at `t_us` (flight clock): what is said is stamped so."""
        self.voice.clock_us = t_us

    def configure(self, limits: MissionLimits, offboard_timeout_s: float,
                  flight: FlightSettings | None) -> None:
        """New parameters: mission limits, COM_OF_LOSS_T, the automatic modes' and POSCTL's
        settings (new stick limits: POSCTL's set-point starts again from here)."""
        self.limits = limits
        self.offboard_timeout_s = offboard_timeout_s
        if flight is not None:
            if flight.sticks != self.flight.sticks:
                self.modes.posctl.restart()
            self.flight = flight

    def reference(self, t_us: int) -> Reference:
        """The desired pose, twist and acceleration at t_us (flight clock)."""
        return self.modes.reference(t_us)

    def fly(self, t_us: int) -> Reference:
        """The reference flown this control period (`reference`), kept as `last_ref`."""
        self.last_ref = self.modes.reference(t_us)
        return self.last_ref

    def land_detector(self, t_us: int, lift_n: float, weight_n: float) -> bool:
        """During a touchdown: True once the vehicle is on the ground (then disarm): held up
        and still for LANDED_STILL_S (`fcu.modes.landing.held_up_and_still`)."""
        return self.modes.descent.detector(t_us, self.state, self.last_ref, lift_n, weight_n)

    def set_touchdown_cap(self, speed_m_s: float) -> None:
        """The touchdown speed the position loop's damping lands at (`fcu.modes.landing`)."""
        self.modes.descent.speed_cap_m_s = speed_m_s

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
        self.modes.posctl.take(now_s, sticks)

    @property
    def sticks_received_s(self) -> float:
        """When the latest MANUAL_CONTROL came (wall clock; -inf: never)."""
        return self.modes.posctl.received_s

    def manual_fresh(self, now_s: float) -> bool:
        """MANUAL_CONTROL heard within COM_RC_LOSS_T (wall clock)."""
        return self.modes.posctl.fresh(now_s, self.flight.manual_timeout_s)

    def _maybe_start_flight(self) -> None:
        if self.armed and self.mode in _FLYING:
            self.flight_started = True

    # ------------------------------------------------------------------ commands

    def arm(self) -> Answer:
        """Arm where the vehicle is: HOLD holds there, POSCTL starts from there (its limits
        fitted again), MISSION flies a mission started before."""
        if self.armed:
            return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, "already armed")
        if self.state is None:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, "arming refused: no state input")
        self.last_ref = None  # hold where the vehicle is, not where an old reference was
        self.armed = True
        self.modes.on_arming()
        self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "armed")
        if self.mode == Mode.POSCTL:
            self._fit_posctl(Mode.POSCTL)  # fitted again there
        run = self.modes.mission_run
        if self.mode == Mode.MISSION and not run.running and not run.done \
                and run.items and self.under_way is None:  # MISSION_START came first: fly
            self._plan_mission(run.current, "", "mission started", (self._warn,))  # it now
        # (POSCTL asked for meanwhile, its fit under way: POSCTL is entered when fitted)
        self._maybe_start_flight()
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, "armed")

    def disarm(self, force: bool = False, reason: str = "disarmed",
               record_in_air: bool = True) -> Answer:
        """Disarm; in the air only with `force`, and then recorded as a crash unless the
        caller records the cause itself (`record_in_air=False`: divergence)."""
        if not self.armed:
            return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, "already disarmed")
        landed = self.landed
        if not force and not landed:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED,
                          "disarm refused: in the air (force with p2 = 21196)")
        self.armed = False  # simulated time keeps running once the flight has started
        self.modes.on_disarming()
        self.drop_under_way()
        self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING if force else MAV_SEVERITY.MAV_SEVERITY_INFO,
                 reason)
        if not landed and record_in_air:
            self.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, "disarmed in the air", CRASH)
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, reason)

    def _mode_refusal(self, mode: Mode, now_s: float) -> str:
        """Why `mode` cannot be entered now ('' when it can, as far as its inputs go)."""
        if mode == Mode.MISSION and not self.modes.mission_run.items:
            return "no mission"
        if mode == Mode.OFFBOARD and (
                self.offboard.received_s + self.offboard_timeout_s < now_s
                or (self.offboard.p_enu_m is None and self.offboard.q_enu_flu is None)):
            return "offboard refused: no setpoint stream"
        if mode == Mode.LAND and not self.armed:
            return "land: not armed"
        if mode in (Mode.TAKEOFF, Mode.RTL) and not self.armed:
            return f"{mode.name.lower()}: not armed"
        if mode == Mode.POSCTL and not self.manual_fresh(now_s):
            return "POSCTL refused: no MANUAL_CONTROL"
        return ""

    def set_mode(self, mode: Mode, now_s: float) -> Answer:
        """(MAV_RESULT, why); IN_PROGRESS while MISSION's plan is made (`_plan_mission`)."""
        refused = self._mode_refusal(mode, now_s)
        if refused:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, refused)
        previous = self.mode
        under_way = self.under_way
        if under_way is not None and under_way.mode == mode:
            return Answer(IN_PROGRESS, "")  # the same mode asked again (another station): it waits
        self.drop_under_way()  # a start under way gives way to the newer command
        run = self.modes.mission_run
        if mode == Mode.MISSION and (previous != Mode.MISSION or not run.running) \
                and self.armed:
            return self._plan_mission(run.current,
                                      "mode MISSION" if previous != mode else "", "mode MISSION")
        if mode == Mode.POSCTL and previous != Mode.POSCTL:
            return self._fit_posctl(previous)
        return self._enter(mode, previous)

    def _enter(self, mode: Mode, previous: Mode) -> Answer:
        """The mode in force from now (its plans made here, cheap ones: TAKEOFF, RTL)."""
        refused = self.modes.plan_auto(mode, previous)
        if refused:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, refused)
        self.modes.switch(mode, previous)
        self._maybe_start_flight()
        if previous != mode:
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, f"mode {mode.name}")
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, f"mode {mode.name}")

    def takeoff(self, target_up_m: float | None = None) -> Answer:
        """MAV_CMD_NAV_TAKEOFF: TAKEOFF, climbing straight up to `target_up_m` above home
        (None: MIS_TAKEOFF_ALT above where the vehicle should be), then HOLD. As PX4 did up to
        1.14 (1.15 and later take the altitude as given), a target less than
        MIS_TAKEOFF_ALT above the vehicle is raised to that, with a warning."""
        if not self.armed:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, "takeoff: not armed")
        climb = self.flight.takeoff_alt_m
        if target_up_m is not None:
            wanted = target_up_m - self.modes.here().p_enu_m[2]
            if not math.isfinite(wanted):
                return Answer(MAV_RESULT.MAV_RESULT_DENIED, "takeoff: altitude not finite")
            if wanted < climb:
                self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING,
                         f"takeoff: using the minimum climb {climb:.1f} m")
            climb = max(climb, wanted)
        refused = self.modes.plan_takeoff(climb)
        if refused:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, refused)
        self.drop_under_way()  # a change under way gives way to the take-off
        previous = self.mode
        self.modes.switch(Mode.TAKEOFF)
        self._maybe_start_flight()
        if previous != Mode.TAKEOFF:
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, f"mode {Mode.TAKEOFF.name}")
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, f"takeoff: climbing {climb:.1f} m")

    def mission_start(self, first: int = 0) -> Answer:
        run = self.modes.mission_run
        if not run.items:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, "no mission")
        if not 0 <= first < len(run.items):
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, f"no mission item {first}")
        self.drop_under_way()
        if self.armed:
            return self._plan_mission(first, "mission started", "mission started")
        run.restart(first)
        self.modes.switch(Mode.MISSION)  # flown when armed
        self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "mission started")
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, "mission started")

    def set_mission(self, items: tuple[MissionItem, ...]) -> None:
        """A new mission (already validated by the mission protocol)."""
        self.modes.mission_run.replace(items)
        self._drop_mission_plan()  # planned for the old one (POSCTL's fit goes on)
        if self.modes.mission_run.has_landing:
            self.modes.say_touchdown_cap()  # the landing's clamp, said when the mission is taken
        if self.mode == Mode.MISSION:
            self.modes.switch(Mode.HOLD, touchdown_goes_on=True)
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "mission replaced: holding")

    def set_mission_current(self, seq: int) -> Answer:
        run = self.modes.mission_run
        if not 0 <= seq < len(run.items):
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, f"no mission item {seq}")
        pending = run.plan
        if pending is not None and pending.seq == seq:
            return Answer(IN_PROGRESS, "")  # asked again (a re-send): it waits for that plan
        if pending is not None:  # a start under way: it flies from `seq` instead, and its
            run.plan = None      # commands wait for that plan's answer
            return self._plan_mission(seq, pending.said, pending.text,
                                      (*pending.replies,))
        if self.mode == Mode.MISSION and run.running and self.armed:
            self.drop_under_way()
            return self._plan_mission(seq, "", f"mission item {seq}")
        run.select(seq)
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, f"mission item {seq}")

    # ------------------------------------------------------------------ changes under way

    def _fit_posctl(self, previous: Mode) -> Answer:
        """POSCTL's limits fitted to the envelope at the desired attitude (`manual.fit_envelope`,
        run by `work`); POSCTL is entered when they are (IN_PROGRESS meanwhile)."""
        start = self.modes.here()
        fit = self.modes.posctl.fit = PosctlFit(previous=previous)
        self.work.submit(manual.fit_envelope, (self.flight.sticks, self.limits.vehicle,
                                               start.q_enu_flu),
                         lambda outcome: self._fitted(fit, outcome))
        return fit.result if fit.result is not None else Answer(IN_PROGRESS, "")

    def _fitted(self, fit: PosctlFit, outcome: Outcome[StickSettings]) -> None:
        if self.modes.posctl.fit is not fit:
            return  # dropped meanwhile
        self.modes.posctl.fit = None
        lim = outcome.value
        if lim is None:
            fit.end(MAV_RESULT.MAV_RESULT_DENIED,
                    f"POSCTL refused: envelope fit failed: {outcome.error}")
            return
        self.modes.posctl.limits = lim
        result = self._enter(Mode.POSCTL, fit.previous)
        if lim.acc_xy_m_s2 < self.flight.sticks.acc_xy_m_s2:  # said, as it is unusual
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO,
                     f"POSCTL: acc {lim.acc_xy_m_s2:.2g} m/s2, jerk "
                     f"{lim.jerk_m_s3:.2g} m/s3 here")
        fit.end(*result)

    def drop_under_way(self) -> None:
        """A mode change under way gives way to a newer command, a disarm or a failsafe
        (also one whose reaction the current mode makes needless: the change would have
        been in force when it came, had it been made in the loop): its command is answered
        MAV_RESULT_FAILED (valid, not carried out; the spec's MAV_RESULT_CANCELLED answers
        COMMAND_CANCEL only), with why."""
        dropped = self.under_way
        self.modes.mission_run.plan = self.modes.posctl.fit = None
        if dropped is not None:
            dropped.end(MAV_RESULT.MAV_RESULT_FAILED, "superseded by a newer command")

    def _drop_mission_plan(self) -> None:
        """A new mission: a mission start under way (planned for the old one) is dropped
        as `drop_under_way` drops it."""
        if self.modes.mission_run.plan is not None:
            self.drop_under_way()

    def _warn(self, result: int, text: str) -> None:
        if result != MAV_RESULT.MAV_RESULT_ACCEPTED:
            self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, text)

    def _plan_mission(self, seq: int, said: str, text: str,
                      replies: tuple[Reply, ...] = ()) -> Answer:
        """Plan the mission from item `seq` from the desired pose at rest (now, or where
        HOLD's brake stops a moving reference: `ModeState.brake_then`) and check it again
        from there with the upload's envelope (`fcu.mission.start.plan_from`, by `work`):
        one that no longer fits is not flown (the vehicle holds; the command is refused with
        the reason). The answer, or IN_PROGRESS meanwhile (then each of `replies` gets it)."""
        plan = self.modes.mission_run.plan = MissionPlan(
            seq=seq, t_s=self.clock_us * 1e-6, start=self.modes.here(), said=said, text=text)
        for reply in replies:
            plan.on_end(reply)
        if self.modes.moving():
            self.modes.brake_then(lambda t_us, at: self._plan_from(plan, t_us, at))
        else:
            self._plan_from(plan, self.clock_us, plan.start)
        return plan.result if plan.result is not None else Answer(IN_PROGRESS, "")

    def _plan_from(self, plan: MissionPlan, t_us: int, start: Reference) -> None:
        plan.t_s, plan.start = t_us * 1e-6, start  # at rest there then
        self.work.submit(plan_from, (self.modes.mission_run.items, self.limits, plan.seq,
                                     plan.t_s, start.p_enu_m, start.q_enu_flu),
                         lambda outcome: self._planned(plan, outcome))

    def _planned(self, plan: MissionPlan,
                 outcome: Outcome[tuple[MissionExecutor | None, str]]) -> None:
        """A mission's plan taken in (at a step boundary): flown from this step on, or
        refused (the vehicle holds where the plan would have started)."""
        run = self.modes.mission_run
        if run.plan is not plan:
            return  # dropped meanwhile
        run.plan = None
        executor, refused = outcome.value if outcome.value is not None else \
            (None, f"mission plan failed: {outcome.error}")
        run.restart(plan.seq)
        if executor is None:
            run.refuse()
            self.modes.switch(Mode.HOLD, hold=plan.start)
            plan.end(MAV_RESULT.MAV_RESULT_DENIED, f"mission refused from here: "
                     f"{result_name(MAV_MISSION_DENIED)}: {refused}")
            return
        self.modes.switch(Mode.MISSION)
        run.begin(executor, self.clock_us * 1e-6 - plan.t_s)  # offset 0 when planned inline
        self.modes.start_taken_in()
        self._maybe_start_flight()
        if plan.said:
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, plan.said)
        plan.end(MAV_RESULT.MAV_RESULT_ACCEPTED, plan.text)

    # ------------------------------------------------------------------ failsafe reactions

    def failsafe_hold(self, reason: str) -> None:
        """A failsafe reaction: stop where the vehicle should be and hold."""
        self.drop_under_way()
        self.modes.switch(Mode.HOLD)
        self.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, reason, FAILSAFE)

    def failsafe_land(self, reason: str) -> None:
        """A failsafe reaction: land where the vehicle is (unless landing already)."""
        self.drop_under_way()
        if self.mode != Mode.LAND:
            self.modes.switch(Mode.LAND)
        self.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, reason, FAILSAFE)
