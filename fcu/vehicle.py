"""The FCU's vehicle logic without I/O: arming, modes, mission and offboard references,
the control step behind the safety gate, and the flight-start latch of lockstep runs.

Simulated (or monotonic) time `t_us` drives control and mission timing; the wall clock
`now_s` is passed in only for link health (offboard stream loss), as DESIGN.md section 2 says.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

from common.config import Gains, VehicleConfig
from common.frames import frd_to_flu, ned_to_enu, q_ned_frd_to_enu_flu
from common.mavlink import MAV
from common.mission_items import MissionItem, local_xy
from common.modes import Mode
from fcu.core import FlightCore, StepResult
from fcu.dualquat import Q_IDENTITY, Quat, Vec3, q_exp, q_normalize
from fcu.mission import MissionEvent, MissionExecutor, MissionLimits
from fcu.safety import gate
from fcu.tracker import Reference, VehicleState

_ZERO: Vec3 = (0.0, 0.0, 0.0)
ACCEPTED = MAV.MAV_RESULT_ACCEPTED
DENIED = MAV.MAV_RESULT_DENIED
FORCE_DISARM_MAGIC = 21196.0  # MAV_CMD_COMPONENT_ARM_DISARM p2 that forces a disarm
LANDED_ALTITUDE_M = 0.05
LANDED_SPEED_M_S = 0.2


class Output(NamedTuple):
    speed_rad_s: tuple[float, ...]
    tilt_rad: tuple[float, ...]
    armed: bool
    result: StepResult | None  # None when the controller did not run (disarmed)


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


@dataclass
class Failsafes:
    """Failsafe settings (parameters COM_*); times in seconds, wall clock for links."""

    gcs_loss_s: float = 0.0  # 0: off
    gcs_loss_land_s: float = 0.0  # 0: hold forever
    state_loss_s: float = 1.0
    saturation_s: float = 2.0  # control time
    saturation_hold: bool = False
    divergence_m: float = 10.0


@dataclass
class Vehicle:
    config: VehicleConfig
    gains: Gains
    control_rate_hz: int
    limits: MissionLimits = field(default_factory=MissionLimits)
    offboard_timeout_s: float = 1.0
    failsafes: Failsafes = field(default_factory=Failsafes)

    def __post_init__(self) -> None:
        self.core = FlightCore(self.config, self.gains, self.control_rate_hz)
        self.armed = False
        self.mode = Mode.HOLD
        self.flight_started = False  # lockstep: simulated time runs once this latches
        self.mission: tuple[MissionItem, ...] = ()
        self.mission_current = 0
        self.executor: MissionExecutor | None = None
        self.mission_running = False
        self.mission_done = False
        self.hold: Reference | None = None
        self.offboard = OffboardSetpoint()
        self.state: VehicleState | None = None
        self.state_time_us = -1
        self.last_ref: Reference | None = None
        self.last_output: Output | None = None
        self.messages: list[tuple[int, str]] = []  # (MAV_SEVERITY, text) to announce
        self.mission_events: list[MissionEvent] = []
        self.land_disarm = False
        self.failsafe = ""  # the active failsafe, announced and shown in HEARTBEAT
        self.gcs_lost_since: float | None = None
        self.saturated_since_us: int | None = None
        self.saturation_reported = False

    # ------------------------------------------------------------------ state

    def say(self, severity: int, text: str) -> None:
        self.messages.append((severity, text[:50]))

    def on_state(self, t_us: int, state: VehicleState) -> None:
        q = q_normalize(state.q_enu_flu)
        self.state = state._replace(q_enu_flu=q)
        self.state_time_us = t_us

    @property
    def landed(self) -> bool:
        s = self.state
        if s is None:
            return True
        speed = math.sqrt(sum(v * v for v in s.v_flu_m_s))
        return s.p_enu_m[2] < LANDED_ALTITUDE_M and speed < LANDED_SPEED_M_S

    def _pose_ref(self, p: Vec3, q: Quat) -> Reference:
        return Reference(p, q, _ZERO, _ZERO, _ZERO, _ZERO)

    def _current_pose_ref(self) -> Reference:
        """Where the vehicle should be now: the last desired pose in flight, else the state."""
        if self.armed and self.last_ref is not None:
            return self._pose_ref(self.last_ref.p_enu_m, self.last_ref.q_enu_flu)
        if self.state is None:
            return self._pose_ref(_ZERO, Q_IDENTITY)
        return self._pose_ref(self.state.p_enu_m, self.state.q_enu_flu)

    # ------------------------------------------------------------------ commands

    def arm(self) -> tuple[int, str]:
        if self.armed:
            return ACCEPTED, "already armed"
        if self.state is None:
            return DENIED, "arming refused: no state input"
        if not all(math.isfinite(x) for x in (*self.state.p_enu_m, *self.state.q_enu_flu)):
            return DENIED, "arming refused: state not finite"
        self.armed = True
        self.failsafe = ""
        self.core.tracker.reset()
        self.hold = self._current_pose_ref()
        self.say(MAV.MAV_SEVERITY_INFO, "armed")
        if self.mode == Mode.MISSION and not self.mission_running and not self.mission_done:
            self._start_mission(resume=True)  # MISSION_START came first: fly it now
        self._maybe_start_flight()
        return ACCEPTED, "armed"

    def disarm(self, force: bool = False, reason: str = "disarmed") -> tuple[int, str]:
        if not self.armed:
            return ACCEPTED, "already disarmed"
        if not force and not self.landed:
            return DENIED, "disarm refused: in the air (force with p2 = 21196)"
        self.armed = False  # simulated time keeps running once the flight has started
        self.mission_running = False
        self.say(MAV.MAV_SEVERITY_INFO if not force else MAV.MAV_SEVERITY_WARNING, reason)
        return ACCEPTED, reason

    def set_mode(self, mode: Mode, now_s: float) -> tuple[int, str]:
        if mode == Mode.MISSION and not self.mission:
            return DENIED, "no mission"
        if mode == Mode.OFFBOARD and (self.offboard.received_s + self.offboard_timeout_s < now_s
                                      or (self.offboard.p_enu_m is None
                                      and self.offboard.q_enu_flu is None)):
            return DENIED, "offboard refused: no setpoint stream"
        previous = self.mode
        self.mode = mode
        if mode == Mode.HOLD:
            self.hold = self._current_pose_ref()
        elif mode == Mode.MISSION and (previous != Mode.MISSION or not self.mission_running):
            self._start_mission(resume=True)
        elif mode == Mode.LAND:
            self._start_landing()
        self._maybe_start_flight()
        if previous != mode:
            self.say(MAV.MAV_SEVERITY_INFO, f"mode {mode.name}")
        return ACCEPTED, f"mode {mode.name}"

    def mission_start(self, first: int = 0) -> tuple[int, str]:
        if not self.mission:
            return DENIED, "no mission"
        if not 0 <= first < len(self.mission):
            return DENIED, f"no mission item {first}"
        self.mission_current = first
        self.mission_done = False
        self.mission_running = False
        self.mode = Mode.MISSION
        self._start_mission(resume=True)
        self._maybe_start_flight()
        self.say(MAV.MAV_SEVERITY_INFO, "mission started")
        return ACCEPTED, "mission started"

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
            self.say(MAV.MAV_SEVERITY_INFO, "mission replaced: holding")

    def set_mission_current(self, seq: int) -> tuple[int, str]:
        if not 0 <= seq < len(self.mission):
            return DENIED, f"no mission item {seq}"
        self.mission_current = seq
        self.mission_done = False
        if self.mode == Mode.MISSION and self.mission_running:
            self._start_mission(resume=True)
        return ACCEPTED, f"mission item {seq}"

    def _maybe_start_flight(self) -> None:
        if self.armed and self.mode in (Mode.MISSION, Mode.OFFBOARD, Mode.LAND):
            self.flight_started = True

    def _start_mission(self, resume: bool) -> None:
        """Plan the mission from the current item, starting now from the desired pose."""
        if not self.armed or not self.mission:
            self.mission_running = False
            return
        start = self._current_pose_ref()
        t_s = max(self.state_time_us, 0) * 1e-6
        self.executor = MissionExecutor(self.mission, self.limits)
        if resume and self.mission_current > 0:
            self.executor.set_current(self.mission_current, t_s, start.p_enu_m,
                                      start.q_enu_flu)
        else:
            self.executor.start(t_s, start.p_enu_m, start.q_enu_flu)
        self.mission_running = True

    def _start_landing(self) -> None:
        start = self._current_pose_ref()
        land = MissionItem(0, MAV.MAV_FRAME_LOCAL_NED, MAV.MAV_CMD_NAV_LAND, 1, 1, 0.0, 0.0,
                           0.0, math.nan, local_xy(start.p_enu_m[1]),
                           local_xy(start.p_enu_m[0]), 0.0)  # x, y: NED (north, east)
        self.land = MissionExecutor((land,), self.limits)
        self.land.start(max(self.state_time_us, 0) * 1e-6, start.p_enu_m, start.q_enu_flu)
        self.land_disarm = True

    # ------------------------------------------------------------------ offboard

    def offboard_position(self, now_s: float, frame: int, type_mask: int, p_ned: Vec3,
                          v_ned: Vec3, a_ned: Vec3, yaw: float) -> tuple[bool, str]:
        """SET_POSITION_TARGET_LOCAL_NED (LOCAL_NED only); type_mask bits ignore fields."""
        if frame != MAV.MAV_FRAME_LOCAL_NED:
            return False, "position target frame must be LOCAL_NED"
        values = [*p_ned, *v_ned, *a_ned, yaw]
        if not all(math.isfinite(x) for x in values[:3]) and not type_mask & 0b111:
            return False, "position target not finite"
        sp = self.offboard
        if not type_mask & 0b111:
            sp.p_enu_m = ned_to_enu(p_ned)
        sp.v_enu_m_s = ned_to_enu(v_ned) if not type_mask & 0b111000 and all(
            map(math.isfinite, v_ned)) else _ZERO
        sp.a_enu_m_s2 = ned_to_enu(a_ned) if not type_mask & 0b111000000 and all(
            map(math.isfinite, a_ned)) else _ZERO
        sp.yaw_ned_rad = yaw if not type_mask & (1 << 10) and math.isfinite(yaw) else None
        sp.received_s = now_s
        return True, ""

    def offboard_attitude(self, now_s: float, type_mask: int, q_ned_frd: Quat,
                          rates_frd: Vec3) -> tuple[bool, str]:
        """SET_ATTITUDE_TARGET: attitude NED->FRD and body rates; bit 7 ignores attitude."""
        sp = self.offboard
        if not type_mask & (1 << 7):
            n = math.sqrt(sum(c * c for c in q_ned_frd))
            if not math.isfinite(n) or n < 0.5:
                return False, "attitude target not a unit quaternion"
            sp.q_enu_flu = q_ned_frd_to_enu_flu(tuple(c / n for c in q_ned_frd))
        rates_ok = all(math.isfinite(x) for x in rates_frd)
        sp.omega_flu_rad_s = frd_to_flu(rates_frd) if rates_ok and not type_mask & 0b111 \
            else _ZERO
        sp.received_s = now_s
        return True, ""

    def _offboard_ref(self) -> Reference:
        sp = self.offboard
        hold = self.hold or self._current_pose_ref()
        p = sp.p_enu_m if sp.p_enu_m is not None else hold.p_enu_m
        if sp.q_enu_flu is not None:
            q = sp.q_enu_flu
        elif sp.yaw_ned_rad is not None:
            q = attitude_from_yaw_ned(sp.yaw_ned_rad)
        else:
            q = hold.q_enu_flu
        return Reference(p, q, sp.v_enu_m_s, sp.a_enu_m_s2, sp.omega_flu_rad_s, _ZERO)

    def _enter_hold(self, reason: str, severity: int = MAV.MAV_SEVERITY_WARNING) -> None:
        self.mode = Mode.HOLD
        self.hold = self._current_pose_ref()
        self.mission_running = False
        self.say(severity, reason)

    def check_links(self, now_s: float, gcs_seen_s: float = math.inf,
                    state_seen_s: float = math.inf) -> None:
        """Link failsafes on the wall clock: offboard stream, GCS heartbeat, state input."""
        fs = self.failsafes
        if self.mode == Mode.OFFBOARD and now_s - self.offboard.received_s > \
                self.offboard_timeout_s:
            self._enter_hold("offboard setpoints lost: HOLD")
        if self.armed and now_s - state_seen_s > fs.state_loss_s:
            self.failsafe = "state input lost"
            self.disarm(force=True, reason="state input lost: disarmed")
            self.say(MAV.MAV_SEVERITY_CRITICAL, "failsafe: no state for "
                     f"{now_s - state_seen_s:.1f} s, motion stopped")
        if fs.gcs_loss_s > 0.0 and math.isfinite(gcs_seen_s):
            lost = now_s - gcs_seen_s > fs.gcs_loss_s
            if lost and self.gcs_lost_since is None:
                self.gcs_lost_since = now_s
                self.failsafe = "GCS link lost"
                if self.armed and self.mode != Mode.LAND:
                    self._enter_hold("failsafe: GCS link lost: HOLD", MAV.MAV_SEVERITY_CRITICAL)
                else:
                    self.say(MAV.MAV_SEVERITY_CRITICAL, "failsafe: GCS link lost")
            elif lost and fs.gcs_loss_land_s > 0.0 and self.armed and \
                    self.mode == Mode.HOLD and now_s - self.gcs_lost_since > fs.gcs_loss_land_s:
                self.set_mode(Mode.LAND, now_s)
                self.say(MAV.MAV_SEVERITY_CRITICAL, "failsafe: GCS link lost: LAND")
            elif not lost and self.gcs_lost_since is not None:
                self.gcs_lost_since = None
                if self.failsafe == "GCS link lost":
                    self.failsafe = ""
                self.say(MAV.MAV_SEVERITY_INFO, "GCS link regained")

    # ------------------------------------------------------------------ control

    def reference(self, t_us: int) -> Reference:
        t_s = t_us * 1e-6
        if self.mode == Mode.MISSION and self.mission_running and self.executor is not None:
            events = self.executor.update(t_s)
            self.mission_events.extend(events)
            for ev in events:
                if ev.kind == "current":
                    self.mission_current = ev.seq
            ref = self.executor.sample(t_s)
            if self.executor.completed:
                self.mission_running = False
                self.mission_done = True
                last = self.mission[-1].command if self.mission else None
                self.mode = Mode.HOLD
                self.hold = self._pose_ref(ref.p_enu_m, ref.q_enu_flu)
                self.land_disarm = last == MAV.MAV_CMD_NAV_LAND
                self.say(MAV.MAV_SEVERITY_INFO, "mission complete")
            return ref
        if self.mode == Mode.OFFBOARD:
            return self._offboard_ref()
        if self.mode == Mode.LAND:
            self.land.update(t_s)
            return self.land.sample(t_s)
        if self.hold is None:
            self.hold = self._current_pose_ref()
        return self.hold

    def _check_saturation(self, t_us: int, saturated: bool) -> None:
        fs = self.failsafes
        if not saturated:
            self.saturated_since_us = None
            self.saturation_reported = False
            if self.failsafe == "rotor saturation":
                self.failsafe = ""
            return
        if self.saturated_since_us is None:
            self.saturated_since_us = t_us
        if not self.saturation_reported and \
                (t_us - self.saturated_since_us) * 1e-6 > fs.saturation_s:
            self.saturation_reported = True
            self.failsafe = "rotor saturation"
            if fs.saturation_hold and self.mode == Mode.MISSION:
                self._enter_hold("failsafe: rotors saturated: mission aborted, HOLD",
                                 MAV.MAV_SEVERITY_CRITICAL)
            else:
                self.say(MAV.MAV_SEVERITY_WARNING, f"rotors saturated for over "
                         f"{fs.saturation_s:g} s")

    def _diverged(self, ref: Reference) -> str:
        s = self.state
        assert s is not None
        values = (*s.p_enu_m, *s.q_enu_flu, *s.v_flu_m_s, *s.omega_flu_rad_s)
        if not all(math.isfinite(v) for v in values):
            return "state not finite"
        err = math.dist(s.p_enu_m, ref.p_enu_m)
        if err > self.failsafes.divergence_m:
            return f"tracking error {err:.1f} m"
        return ""

    def step(self, t_us: int) -> Output:
        """One control period at time t_us on the latest state."""
        n = self.config.n_rotors
        held = tuple(self.core.allocator.tilt)
        if self.state is None or not self.armed:
            out = gate(False, (0.0,) * n, held, held)
            self.last_output = Output(out.speed_rad_s, out.tilt_rad, False, None)
            return self.last_output
        ref = self.reference(t_us)
        result = self.core.step(self.state, ref)
        self.last_ref = ref
        alloc = result.allocation
        out = gate(True, alloc.speed_rad_s, alloc.tilt_rad, held)
        diverged = self._diverged(ref)
        if out.fault or diverged:
            self.armed = False
            self.mission_running = False
            self.failsafe = "diverged" if diverged else "non-finite command"
            if out.fault:
                self.core.allocator.reset(held)
            else:
                out = gate(False, (0.0,) * n, out.tilt_rad, held)
            self.say(MAV.MAV_SEVERITY_EMERGENCY, f"failsafe: {diverged or out.fault}: disarmed")
            self.last_output = Output(out.speed_rad_s, out.tilt_rad, False, result)
            return self.last_output
        self._check_saturation(t_us, alloc.saturated)
        if self.land_disarm and self.landed and (
                (self.mode == Mode.LAND and self.land.completed) or self.mode == Mode.HOLD):
            self.land_disarm = False
            self.disarm(reason="landed: disarmed")
            out = gate(False, (0.0,) * n, out.tilt_rad, held)
        self.last_output = Output(out.speed_rad_s, out.tilt_rad, self.armed, result)
        return self.last_output


def attitude_from_yaw_ned(yaw_ned_rad: float) -> Quat:
    """Level attitude (ENU/FLU) heading at a NED yaw: ENU yaw = pi/2 - NED yaw."""
    return q_exp((0.0, 0.0, math.pi / 2 - yaw_ned_rad))
