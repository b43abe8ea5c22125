"""The commander stage: arming, modes and which reference flies (mission, offboard, hold,
land, takeoff, return, position control), without I/O; the references themselves are flown
by its base, `fcu.modes.mode_references`.

Time comes in as arguments: `t_us` is the flight clock (simulated in lockstep, monotonic in
real time) for everything that shapes the flight; `now_s` is the wall clock, used only for
the offboard stream's freshness (docs/clocks.md). What the commander says goes into
`events` (on the flight clock); the process shell turns them into STATUSTEXT.

Landing (LAND mode, or a mission whose last item is NAV_LAND): the descent to the ground
plane follows its planned profile; then the set-point sinks and the land detector disarms
(`fcu.modes.landing`): a landing ends on the ground, disarmed, never hovering armed.

TAKEOFF climbs `FlightSettings.takeoff_alt_m` (MIS_TAKEOFF_ALT) straight up from where the
vehicle should be, then holds (HOLD). RTL climbs to `rtl_return_alt_m` (RTL_RETURN_ALT)
above home if it is lower, flies to home's north and east at `rtl_cruise_m_s` (MPC_XY_CRUISE)
and lands there as LAND does. Both are planned as missions (NAV_TAKEOFF, NAV_WAYPOINT,
NAV_LAND items: `fcu.modes.auto_plans`) by the mission executor, so their legs are quintic
profiles stretched until the vehicle can fly them (`fcu.mission`, `fcu.envelope.feasibility`). Home
is the origin of the local frame (HOME_POSITION). POSCTL moves the set-point as
MANUAL_CONTROL's sticks say (`fcu.modes.manual`); the stream's freshness is checked on the wall
clock like the offboard one.
The FCU's MAVLink edge (`fcu.edge.setpoint_wire`) decodes the offboard and manual set-points; the
commander takes them typed, in ENU/FLU and SI units.

A mission's start (MISSION_START, mode MISSION, a new current item in flight, arming in
MISSION) plans the mission from the desired pose and checks it again: a job for `work`
(`fcu.work`). Where it runs beside the loop the command's answer is IN_PROGRESS
(`MAV_RESULT_IN_PROGRESS`; every command waiting on it is told the final one,
`UnderWay.end`): the mode in force flies on, the HEARTBEAT shows it, until the plan is taken
in at a step boundary (`_planned`); its timeline then starts at that step
(`mission_offset_s`). The same mode asked for again meanwhile waits for the same end; any
other mode change, a disarm, a failsafe or a new mission drops a plan under way.
"""

from __future__ import annotations

import math
from dataclasses import replace

from common.outcome import CRASH, FAILSAFE
from common.wire.mav_enums import MAV_CMD, MAV_RESULT, MAV_SEVERITY
from common.wire.mission_items import MissionItem
from common.wire.modes import Mode
from fcu.mission.codes import MAV_MISSION_DENIED, result_name
from fcu.mission.executor import MissionExecutor
from fcu.mission.start import MissionPlan, PosctlFit, plan_from
from fcu.modes import auto_plans, manual
from fcu.modes.answer import Answer, Reply
from fcu.modes.manual import StickSettings
from fcu.modes.mode_references import ModeReferences
from fcu.work import Outcome

IN_PROGRESS = MAV_RESULT.MAV_RESULT_IN_PROGRESS  # answered later, through UnderWay.end


class Commander(ModeReferences):
    """Arming, modes and commands: what `ModeReferences` flies next."""

    # ------------------------------------------------------------------ commands

    def arm(self) -> Answer:
        if self.armed:
            return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, "already armed")
        if self.state is None:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, "arming refused: no state input")
        self.last_ref = None  # hold where the vehicle is, not where an old reference was
        self.armed = True
        self.hold = self._current_pose_ref()
        self.touchdown = None
        self.manual_sp = None  # POSCTL starts from where the vehicle is
        self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "armed")
        if self.mode == Mode.POSCTL:
            self._fit_posctl(Mode.POSCTL)  # fitted again there
        if self.mode == Mode.MISSION and not self.mission_running and not self.mission_done \
                and self.mission:  # MISSION_START came first: fly it now
            self._plan_mission(self.mission_current, "", "mission started", self._warn)
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
        self.mission_running = False
        self._drop_under_way()
        self.touchdown = None
        self.land = None
        self.auto = None
        self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING if force else MAV_SEVERITY.MAV_SEVERITY_INFO,
                 reason)
        if not landed and record_in_air:
            self.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, "disarmed in the air", CRASH)
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, reason)

    def _mode_refusal(self, mode: Mode, now_s: float) -> str:
        """Why `mode` cannot be entered now ('' when it can, as far as its inputs go)."""
        if mode == Mode.MISSION and not self.mission:
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
        self._drop_under_way()  # a start under way gives way to the newer command
        if mode == Mode.MISSION and (previous != Mode.MISSION or not self.mission_running) \
                and self.armed:
            return self._plan_mission(self.mission_current,
                                      "mode MISSION" if previous != mode else "", "mode MISSION")
        if mode == Mode.POSCTL and previous != Mode.POSCTL:
            return self._fit_posctl(previous)
        return self._enter(mode, previous)

    def _enter(self, mode: Mode, previous: Mode) -> Answer:
        """The mode in force from now (its plans made here, cheap ones: TAKEOFF, RTL)."""
        idle = self.auto is None and self.touchdown is None  # e.g. landed, disarmed, re-armed
        if mode == Mode.TAKEOFF and (previous != Mode.TAKEOFF or idle):
            refused = self._start_takeoff(self.flight.takeoff_alt_m)
            if refused:
                return Answer(MAV_RESULT.MAV_RESULT_DENIED, refused)
        elif mode == Mode.RTL and (previous != Mode.RTL or idle):
            refused = self._start_rtl()
            if refused:
                return Answer(MAV_RESULT.MAV_RESULT_DENIED, refused)
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
            self.mission_running = False  # disarmed: it starts when armed
        elif mode == Mode.LAND and previous != Mode.LAND:
            self._start_landing()
        elif mode == Mode.OFFBOARD:
            self.mission_running = False
            if previous != Mode.OFFBOARD:
                self.offboard_sp = None  # the approach starts from the reference flown
        self._maybe_start_flight()
        if previous != mode:
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, f"mode {mode.name}")
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, f"mode {mode.name}")

    def takeoff(self, target_up_m: float | None = None) -> Answer:
        """MAV_CMD_NAV_TAKEOFF: TAKEOFF, climbing straight up to `target_up_m` above home
        (None: MIS_TAKEOFF_ALT above where the vehicle should be), then HOLD. As PX4 does, a
        target less than MIS_TAKEOFF_ALT above the vehicle is raised to that, with a
        warning."""
        if not self.armed:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, "takeoff: not armed")
        climb = self.flight.takeoff_alt_m
        if target_up_m is not None:
            wanted = target_up_m - self._current_pose_ref().p_enu_m[2]
            if not math.isfinite(wanted):
                return Answer(MAV_RESULT.MAV_RESULT_DENIED, "takeoff: altitude not finite")
            if wanted < climb:
                self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING,
                         f"takeoff: using the minimum climb {climb:.1f} m")
            climb = max(climb, wanted)
        refused = self._start_takeoff(climb)
        if refused:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, refused)
        previous = self.mode
        self.mode = Mode.TAKEOFF
        self.touchdown = None
        self.land = None
        self.mission_running = False
        self._maybe_start_flight()
        if previous != Mode.TAKEOFF:
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, f"mode {Mode.TAKEOFF.name}")
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, f"takeoff: climbing {climb:.1f} m")

    def _start_takeoff(self, climb_m: float) -> str:
        """Plan TAKEOFF's climb (one NAV_TAKEOFF item); a reason if refused, else ""."""
        start = self._current_pose_ref()
        items = auto_plans.takeoff(start.p_enu_m, climb_m, self.limits.max_distance_m)
        if isinstance(items, str):
            return items
        self.auto = MissionExecutor(items, self.limits)
        self.auto.start(self.clock_us * 1e-6, start.p_enu_m, start.q_enu_flu)
        return ""

    def _start_rtl(self) -> str:
        """Plan RTL (module docstring): climb to RTL_RETURN_ALT if lower, travel home at
        MPC_XY_CRUISE, land; a reason if refused, else ""."""
        start = self._current_pose_ref()
        items = auto_plans.rtl(start.p_enu_m, self.flight.rtl_return_alt_m,
                               self.limits.max_distance_m)
        if isinstance(items, str):
            return items
        limits = replace(self.limits, cruise_speed_m_s=self.flight.rtl_cruise_m_s)
        self.auto = MissionExecutor(items, limits)
        self.auto.start(self.clock_us * 1e-6, start.p_enu_m, start.q_enu_flu)
        self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, f"RTL: return at {-items[0].z:.1f} m, then land")
        return ""

    def mission_start(self, first: int = 0) -> Answer:
        if not self.mission:
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, "no mission")
        if not 0 <= first < len(self.mission):
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, f"no mission item {first}")
        self._drop_under_way()
        if self.armed:
            return self._plan_mission(first, "mission started", "mission started")
        self.mission_current = first
        self.mission_done = False
        self.mission_running = False
        self.mode = Mode.MISSION  # flown when armed
        self.touchdown = None
        self.land = None
        self.auto = None
        self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "mission started")
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, "mission started")

    def set_mission(self, items: tuple[MissionItem, ...]) -> None:
        """A new mission (already validated by the mission protocol)."""
        self.mission = tuple(items)
        self.mission_current = 0
        self.mission_done = False
        self.executor = None
        self._drop_under_way()  # planned for the old one
        if any(it.command == MAV_CMD.MAV_CMD_NAV_LAND for it in self.mission):
            self.say_touchdown_cap()  # the landing's clamp, said when the mission is taken
        if self.mode == Mode.MISSION:
            self.mode = Mode.HOLD
            self.hold = self._current_pose_ref()
            self.mission_running = False
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "mission replaced: holding")

    def set_mission_current(self, seq: int) -> Answer:
        if not 0 <= seq < len(self.mission):
            return Answer(MAV_RESULT.MAV_RESULT_DENIED, f"no mission item {seq}")
        if self.mode == Mode.MISSION and self.mission_running and self.armed:
            self._drop_under_way()
            return self._plan_mission(seq, "", f"mission item {seq}")
        self.mission_current = seq
        self.mission_done = False
        return Answer(MAV_RESULT.MAV_RESULT_ACCEPTED, f"mission item {seq}")

    def _maybe_start_flight(self) -> None:
        if self.armed and self.mode in (Mode.MISSION, Mode.OFFBOARD, Mode.LAND, Mode.TAKEOFF,
                                        Mode.RTL, Mode.POSCTL):
            self.flight_started = True

    def _fit_posctl(self, previous: Mode) -> Answer:
        """POSCTL's limits fitted to the envelope at the desired attitude (`manual.fit_envelope`,
        run by `work`); POSCTL is entered when they are (IN_PROGRESS meanwhile)."""
        start = self._current_pose_ref()
        fit = self.posctl_fit = PosctlFit(previous=previous)
        self.work.submit(manual.fit_envelope, (self.flight.sticks, self.limits.vehicle,
                                               start.q_enu_flu),
                         lambda outcome: self._fitted(fit, outcome))
        return fit.result if fit.result is not None else Answer(IN_PROGRESS, "")

    def _fitted(self, fit: PosctlFit, outcome: Outcome[StickSettings]) -> None:
        if self.posctl_fit is not fit:
            return  # dropped meanwhile
        self.posctl_fit = None
        lim = outcome.value
        if lim is None:
            fit.end(MAV_RESULT.MAV_RESULT_DENIED,
                    f"POSCTL refused: envelope fit failed: {outcome.error}")
            return
        self.manual_limits = lim
        result = self._enter(Mode.POSCTL, fit.previous)
        if lim.acc_xy_m_s2 < self.flight.sticks.acc_xy_m_s2:  # said, as it is unusual
            self.say(MAV_SEVERITY.MAV_SEVERITY_INFO,
                     f"POSCTL: acc {lim.acc_xy_m_s2:.2g} m/s2, jerk "
                     f"{lim.jerk_m_s3:.2g} m/s3 here")
        fit.end(*result)

    def _drop_under_way(self) -> None:
        """A mode change under way gives way to a newer command, a new mission, a disarm or
        a failsafe: its command is answered MAV_RESULT_FAILED (valid, not carried out; the
        spec's MAV_RESULT_CANCELLED answers COMMAND_CANCEL only), with why."""
        dropped = self.under_way
        self.mission_plan = self.posctl_fit = None
        if dropped is not None:
            dropped.end(MAV_RESULT.MAV_RESULT_FAILED, "superseded by a newer command")

    @property
    def under_way(self) -> MissionPlan | PosctlFit | None:
        """The mode change whose work runs beside the loop (its waiting commands told the end)."""
        return self.mission_plan or self.posctl_fit

    def _warn(self, result: int, text: str) -> None:
        if result != MAV_RESULT.MAV_RESULT_ACCEPTED:
            self.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, text)

    def _plan_mission(self, seq: int, said: str, text: str,
                      reply: Reply | None = None) -> Answer:
        """Plan the mission from item `seq`, starting now from the desired pose, and check
        it again from there with the upload's envelope (`fcu.mission.start.plan_from`, run
        by `work`): one that no longer fits is not flown (the vehicle holds; the command is
        refused with the reason), never flown into the limits. The answer, or IN_PROGRESS
        while the plan is made beside the loop (then `reply` gets it)."""
        start = self._current_pose_ref()
        plan = self.mission_plan = MissionPlan(seq=seq, t_s=self.clock_us * 1e-6, start=start,
                                               said=said, text=text)
        if reply is not None:
            plan.on_end(reply)
        self.work.submit(plan_from, (self.mission, self.limits, seq, plan.t_s, start.p_enu_m,
                                     start.q_enu_flu),
                         lambda outcome: self._planned(plan, outcome))
        return plan.result if plan.result is not None else Answer(IN_PROGRESS, "")

    def _planned(self, plan: MissionPlan,
                 outcome: Outcome[tuple[MissionExecutor | None, str]]) -> None:
        """A mission's plan taken in (at a step boundary): flown from this step on, or
        refused (the vehicle holds where the plan would have started)."""
        if self.mission_plan is not plan:
            return  # dropped meanwhile
        self.mission_plan = None
        executor, refused = outcome.value if outcome.value is not None else \
            (None, f"mission plan failed: {outcome.error}")
        self.mission_current = plan.seq
        self.mission_done = False
        self.mode = Mode.MISSION
        self.touchdown = None
        self.land = None
        self.auto = None
        if executor is None:
            self.executor = None
            self.mission_running = False
            self.mode = Mode.HOLD
            self.hold = plan.start
            plan.end(MAV_RESULT.MAV_RESULT_DENIED, f"mission refused from here: "
                     f"{result_name(MAV_MISSION_DENIED)}: {refused}")
        else:
            self.executor = executor
            self.mission_running = True
            self.mission_offset_s = self.clock_us * 1e-6 - plan.t_s  # 0 when planned inline
            self._maybe_start_flight()
            if plan.said:
                self.say(MAV_SEVERITY.MAV_SEVERITY_INFO, plan.said)
            plan.end(MAV_RESULT.MAV_RESULT_ACCEPTED, plan.text)

    def _start_landing(self) -> None:
        start = self._current_pose_ref()
        self.land = MissionExecutor(auto_plans.land(), self.limits)
        self.land.start(self.clock_us * 1e-6, start.p_enu_m, start.q_enu_flu)
        self.touchdown = None

    # ------------------------------------------------------------------ failsafe reactions

    @property
    def landing(self) -> bool:
        """Landing or returning: LAND or RTL mode, a touchdown, or a mission flying its
        NAV_LAND item (a GCS link loss does not interrupt these)."""
        if self.mode in (Mode.LAND, Mode.RTL) or self.touchdown is not None:
            return True
        return self.mode == Mode.MISSION and self.mission_running and \
            0 <= self.mission_current < len(self.mission) and \
            self.mission[self.mission_current].command == MAV_CMD.MAV_CMD_NAV_LAND

    def failsafe_hold(self, reason: str) -> None:
        """A failsafe reaction: stop where the vehicle should be and hold."""
        self._drop_under_way()
        self.mode = Mode.HOLD
        self.hold = self._current_pose_ref()
        self.mission_running = False
        self.touchdown = None
        self.land = None
        self.auto = None
        self.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, reason, FAILSAFE)

    def failsafe_land(self, reason: str) -> None:
        self._drop_under_way()
        if self.mode != Mode.LAND:
            self.mode = Mode.LAND
            self.auto = None
            self._start_landing()
        self.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, reason, FAILSAFE)
