"""The FCU's pipeline, one tick at a time (Crazyflie's stabilizer loop, PX4's modules):

    state input or estimator (IMU + pose) -> commander (reference)
                -> controller (tracker, eq. 16/33) -> allocator (eq. 28-29)
                -> supervisor (the one output gate) -> outputs

The state is either the exact state from the simulator link (ODOMETRY; parameter
EKF_EN = 0) or the estimator's output at the newest IMU sample, with the bias-corrected
rate (EKF_EN = 1: `on_imu`, `on_pose`; fcu/estimator/).

Pure and I/O-free: the flight clock `t_us` and the period `dt_s` come in as arguments (the
process shell passes simulated time in lockstep and the measured, clamped period in real
time); the wall clock `now_s` reaches only `check_links`. The same pipeline runs in the FCU
process and in the in-process runner, so both fly the same controller with the same modes,
mission executor, failsafes and events.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from common.config.scenario import Gains, VehicleConfig
from common.outcome import DIVERGED, FAILSAFE, INFO, LIMIT, Event, diverged
from common.wire.mav_enums import MAV_RESULT, MAV_SEVERITY
from common.wire.modes import Mode
from fcu.control.core import FlightCore, StepResult
from fcu.control.dualquat import q_normalize, q_rotate
from fcu.control.rate_filter import ImuRateFilter
from fcu.estimator.ekf import Estimator
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.estimator.settings import EstimatorSettings
from fcu.mission.limits import MissionLimits
from fcu.modes.answer import Answer
from fcu.modes.commander import Commander
from fcu.modes.landing import touchdown_speed_cap
from fcu.modes.settings import FlightSettings
from fcu.safety.actuator_monitor import ActuatorMonitor, unclamped_speeds
from fcu.safety.failsafe import (
    Failsafe,
    FailsafeSettings,
    GcsLinkMonitor,
    LinkChange,
    PoseLoss,
    SaturationChange,
    SaturationMonitor,
    manual_control_lost,
    offboard_lost,
    pose_loss_level,
    state_lost,
)
from fcu.safety.supervisor import Supervisor
from fcu.stages import VehicleState

ALIGN_MAX_S = 60.0  # lockstep: simulated time runs for the alignment at most this long


class StepOutput(NamedTuple):
    """What one tick sends to the actuators, and what the controller computed."""

    t_us: int  # the stamp of the state it answers
    speed_rad_s: tuple[float, ...]
    tilt_rad: tuple[float, ...]
    armed: bool
    result: StepResult | None  # None when the controller did not run (disarmed)


class Pipeline:
    def __init__(self, vehicle: VehicleConfig, gains: Gains, control_rate_hz: int, *,
                 limits: MissionLimits | None = None,
                 failsafes: FailsafeSettings | None = None,
                 initial_tilt_rad: tuple[float, ...] | None = None) -> None:
        self.vehicle = vehicle
        self.period_us = 1_000_000 // control_rate_hz
        self.weight_n = vehicle.mass_kg * vehicle.gravity_m_s2
        self.core = FlightCore(vehicle, gains, control_rate_hz, initial_tilt_rad)
        self.commander = Commander(limits or MissionLimits(vehicle=vehicle))
        self._set_touchdown_cap(gains)
        self.settings = failsafes or FailsafeSettings()
        self.supervisor = Supervisor(vehicle.n_rotors, vehicle.rotor_speed_max_rad_s,
                                     initial_tilt_rad)
        self.saturation = SaturationMonitor()
        self.actuators = ActuatorMonitor(vehicle.n_rotors, vehicle.tilt_rate_max_rad_s,
                                         vehicle.rotor_speed_max_rad_s,
                                         self.core.allocator.hold_speed,
                                         self.core.allocator.tilt)
        self.gcs_link = GcsLinkMonitor()
        self.state: VehicleState | None = None
        self.state_time_us = -1  # the stamp of the latest state or IMU sample (answers echo it)
        # The simulator's stamp of the control period the next step answers: the newest
        # state's, or with the estimator the newest IMU sample at a period's end (where the
        # estimate is taken). In lockstep the step comes at that instant; in real time a
        # newer sample may have come since (with a 1 kHz IMU, the odd millisecond's).
        self.period_stamp_us = -1
        self.state_rx_us: int | None = None  # the flight clock when it arrived
        self.failsafe: Failsafe = Failsafe.NONE  # in force: shown in HEARTBEAT, SYS_STATUS
        self.last_output: StepOutput | None = None
        self.steps = 0
        self.saturated_steps = 0
        self.tilt_rate_limited_steps = 0  # armed periods with a tilt servo rate-limited
        self.estimator: Estimator | None = None  # EKF_EN = 1
        self.rate_filter = ImuRateFilter(0.0)  # IMU_GYRO_CUTOFF: the rate's low-pass
        self.pose_level = PoseLoss.FRESH  # pose loss (failsafe.pose_loss_level)
        self.flight_start_us: int | None = None  # the flight clock at the flight's start
        # A logger sets this to a list: every input handed to the estimator is appended, in
        # arrival order, for the logger to drain (the onboard log's sensor topics). None
        # keeps nothing.
        self.estimator_inputs: list[ImuInput | PoseInput] | None = None
        self._align_timeout_said = False

    # ------------------------------------------------------------------ inputs

    def on_state(self, stamp_us: int, state: VehicleState, rx_us: int) -> None:
        """A valid state stamped `stamp_us`, received at `rx_us` on the flight clock."""
        p, q, v, w = state
        self._take_state(stamp_us, VehicleState(p, q_normalize(q), v, w), rx_us)
        self.period_stamp_us = stamp_us

    def _take_state(self, stamp_us: int, state: VehicleState, rx_us: int) -> None:
        """`on_state` of a state whose attitude is normalized."""
        self.state = state
        self.state_time_us = stamp_us
        self.state_rx_us = rx_us
        self.commander.on_state(state, rx_us)

    def use_estimator(self, settings: EstimatorSettings | None) -> None:
        """Fly on the estimator with these settings, or (None) on the exact state input.
        Switching resets the estimator: it aligns again (refused while armed)."""
        if settings is None:
            self.estimator = None
        elif self.estimator is None or self.estimator.settings != settings:
            self.estimator = Estimator(settings)
            self.state = None
            self.commander.drop_state()
            self.rate_filter = ImuRateFilter(self.rate_filter.cutoff_hz)

    def set_gyro_cutoff(self, cutoff_hz: float) -> None:
        """IMU_GYRO_CUTOFF; a change restarts the filter (at the IMU's rate)."""
        if cutoff_hz != self.rate_filter.cutoff_hz:
            self.rate_filter = ImuRateFilter(cutoff_hz)

    def on_imu(self, sample: ImuInput) -> None:
        """One IMU sample (HIL_SENSOR) for the estimator; its stamp is the state's."""
        est = self.estimator
        if est is None:
            return
        if self.estimator_inputs is not None:
            self.estimator_inputs.append(sample)
        est.on_imu(sample)
        self.rate_filter.update(sample.t_us, sample.omega_flu_rad_s)
        if sample.t_us > self.state_time_us:
            self.state_time_us = sample.t_us  # answers echo the newest sample
        if sample.t_us % self.period_us == 0:
            self._take_estimate()  # the state of the period (telemetry, arming, the step)
            if sample.t_us > self.period_stamp_us:  # a late, reordered sample answers none
                self.period_stamp_us = sample.t_us

    def on_pose(self, pose: PoseInput) -> None:
        """One external pose (motion capture) for the estimator."""
        if self.estimator is not None:
            if self.estimator_inputs is not None:
                self.estimator_inputs.append(pose)
            self.estimator.on_pose(pose)

    @property
    def estimator_ready(self) -> bool:
        """Aligned and converged (arming needs it); always true without an estimator."""
        est = self.estimator
        if est is None:
            return True
        st = est.health()
        return st.aligned and st.converged and st.healthy

    @property
    def needs_time(self) -> bool:
        """In lockstep, periods before the flight that the FCU answers (disarmed): the
        estimator aligns on the vehicle at rest while simulated time runs, for at most
        ALIGN_MAX_S of it (then the FCU says so once and waits, as without a sensor)."""
        if self.commander.flight_started or self.estimator_ready:
            return False
        if self.state_time_us < ALIGN_MAX_S * 1_000_000:
            return True
        if not self._align_timeout_said:
            self._align_timeout_said = True
            self.commander.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL,
                               f"estimator not aligned in {ALIGN_MAX_S:g} s: waiting")
        return False

    def _take_estimate(self) -> None:
        out = None if self.estimator is None else self.rate_filter.flown(self.estimator)
        if out is not None:  # its output, low-passed and normalized: one compiled call
            t_us, state = out
            stamp = self.state_time_us
            self._take_state(t_us, state, t_us)
            self.state_time_us = max(stamp, t_us)

    def configure(self, gains: Gains, limits: MissionLimits, failsafes: FailsafeSettings,
                  offboard_timeout_s: float, flight: FlightSettings | None = None) -> None:
        """New parameters: gains, mission limits, failsafe settings, the automatic modes' and
        POSCTL's settings."""
        self.core.tracker.set_gains(gains)
        self._set_touchdown_cap(gains)
        self.commander.configure(limits, offboard_timeout_s, flight)
        self.settings = failsafes

    def _set_touchdown_cap(self, gains: Gains) -> None:
        """The touchdown speed the position loop's damping lands at (`fcu.modes.landing`)."""
        self.commander.set_touchdown_cap(touchdown_speed_cap(max(gains.kd_d),
                                                             self.vehicle.gravity_m_s2))

    def arm(self) -> Answer:
        was = self.commander.armed
        if not was and self.estimator is not None:
            st = self.estimator.health()
            why = ("not aligned" if not st.aligned else "not converged" if not st.converged
                   else "unhealthy" if not st.healthy else "")  # within one STATUSTEXT
            if why:
                return Answer(MAV_RESULT.MAV_RESULT_TEMPORARILY_REJECTED,
                              f"arming refused: estimator {why}")
        result = self.commander.arm()
        if result[0] == MAV_RESULT.MAV_RESULT_ACCEPTED and not was:
            self.core.tracker.reset()
            self.saturation = SaturationMonitor()
            self.actuators.reset(self.core.allocator.tilt)
            self.failsafe = Failsafe.NONE
            self.pose_level = PoseLoss.FRESH
        return result

    @property
    def events(self) -> list[Event]:
        return self.commander.events

    @property
    def armed(self) -> bool:
        return self.commander.armed

    @property
    def flight_started(self) -> bool:
        return self.commander.flight_started

    # ------------------------------------------------------------------ the tick

    def step(self, t_us: int, dt_s: float | None = None) -> StepOutput:
        """One control period at t_us (flight clock) on the latest state."""
        cmd = self.commander
        cmd.step_at(t_us)
        self.steps += 1
        if cmd.flight_started and self.flight_start_us is None:
            self.flight_start_us = t_us
        if cmd.armed and self.estimator is not None:
            self._check_estimator(t_us)
        if cmd.armed and state_lost(t_us, self.state_rx_us, self.settings):
            self.failsafe = Failsafe.STATE_LOST
            cmd.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, "failsafe: state input lost", FAILSAFE)
            cmd.disarm(force=True, reason="state input lost: disarmed")
        state = self.state
        if state is None or not cmd.armed:
            out = self.supervisor.gate(False, self.supervisor.zero, tuple(self.core.allocator.tilt))
            self.actuators.reset(out.tilt_rad)  # the servos settle on what is sent
            return self._output(out.speed_rad_s, out.tilt_rad, None)
        ref = cmd.fly(t_us)
        result = self.core.step(state, ref, dt_s)
        alloc = result.allocation
        err = math.dist(state.p_enu_m, ref.p_enu_m)
        p, q, v, w = state  # a finite sum: all finite; else (NaN, inf, overflow) each one
        finite = math.isfinite(p[0] + p[1] + p[2] + q[0] + q[1] + q[2] + q[3] + v[0] + v[1] +
                               v[2] + w[0] + w[1] + w[2]) or all(map(math.isfinite,
                                                                      (*p, *q, *v, *w)))
        if diverged(err, finite, self.settings.divergence_m):
            self.failsafe = Failsafe.DIVERGED
            cmd.say(MAV_SEVERITY.MAV_SEVERITY_EMERGENCY, f"failsafe: diverged ({err:.1f} m)",
                    DIVERGED)
            cmd.disarm(force=True, reason="diverged: disarmed", record_in_air=False)
            out = self.supervisor.gate(False, alloc.speed_rad_s, alloc.tilt_rad)
            return self._output(out.speed_rad_s, out.tilt_rad, result)
        out = self.supervisor.gate(True, alloc.speed_rad_s, alloc.tilt_rad)
        if out.fault:
            self.core.allocator.reset(out.tilt_rad)
            self.failsafe = Failsafe.NON_FINITE
            cmd.say(MAV_SEVERITY.MAV_SEVERITY_EMERGENCY, "failsafe: non-finite actuator command",
                    FAILSAFE)
            cmd.disarm(force=True, reason="non-finite command: disarmed")
            return self._output(out.speed_rad_s, out.tilt_rad, result)
        if alloc.saturated:
            self.saturated_steps += 1
        self._check_saturation(t_us, alloc.saturated, alloc.omega_sq)
        self._check_actuators(self.core.dt_s if dt_s is None else dt_s, out.tilt_rad,
                              alloc.omega_sq)
        lift_n = q_rotate(state.q_enu_flu, result.tracker.force_flu_n)[2]
        if cmd.land_detector(t_us, lift_n, self.weight_n):
            cmd.disarm(reason="landed: disarmed")
            out = self.supervisor.gate(False, out.speed_rad_s, out.tilt_rad)
        return self._output(out.speed_rad_s, out.tilt_rad, result)

    def _output(self, speeds: tuple[float, ...], tilts: tuple[float, ...],
                result: StepResult | None) -> StepOutput:
        self.last_output = StepOutput(max(self.state_time_us, 0), speeds, tilts,
                                      self.commander.armed, result)
        return self.last_output

    def _check_estimator(self, t_us: int) -> None:
        """Estimator failsafes: a failed estimate disarms (nothing to fly on); a pose source
        lost dead-reckons for COM_POS_LOSS_T, then HOLD, then LAND after COM_POS_LAND_T;
        EKF_GATE_N poses refused in a row (inconsistent): LAND."""
        assert self.estimator is not None
        st = self.estimator.health()
        cmd = self.commander
        if not st.healthy:
            self.failsafe = Failsafe.ESTIMATOR_FAILED
            cmd.say(MAV_SEVERITY.MAV_SEVERITY_EMERGENCY, "failsafe: estimator failed", FAILSAFE)
            cmd.disarm(force=True, reason="estimator failed: disarmed")
            return
        if st.rejected_in_row >= self.settings.gate_failures and \
                self.failsafe is not Failsafe.ESTIMATOR_INCONSISTENT:
            self.failsafe = Failsafe.ESTIMATOR_INCONSISTENT
            cmd.failsafe_land("failsafe: estimator inconsistent: LAND")
        level = pose_loss_level(t_us, st.last_fusion_us, self.settings)
        if level > self.pose_level:
            self.failsafe = Failsafe.POSE_LOST
            if level is PoseLoss.HOLD and not cmd.landing_ahead:
                cmd.failsafe_hold("failsafe: pose source lost: HOLD")
            elif level is PoseLoss.LAND:
                cmd.failsafe_land("failsafe: pose source lost: LAND")
        elif level is PoseLoss.FRESH and self.pose_level > PoseLoss.FRESH:
            if self.failsafe is Failsafe.POSE_LOST:
                self.failsafe = Failsafe.NONE
            cmd.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "pose source regained")
        self.pose_level = level

    def _check_actuators(self, dt_s: float, tilt_rad: tuple[float, ...],
                         omega_sq: tuple[float, ...]) -> None:
        """The actuators against their models (COM_ACT_RATE_T): a WARNING once per
        episode for each tilt servo rate-limited or rotor at its speed limit for longer (an
        event of kind LIMIT: the run's status is `limited`), an INFO when they all cleared;
        reports only, the commands are not changed."""
        limit_s = self.settings.actuator_limit_s
        for notice in self.actuators.update_from_allocation(dt_s, tilt_rad, omega_sq, limit_s):
            if notice.kind == "clear":
                self.commander.say(MAV_SEVERITY.MAV_SEVERITY_INFO, notice.text(limit_s), INFO)
            else:
                self.commander.say(MAV_SEVERITY.MAV_SEVERITY_WARNING, notice.text(limit_s),
                                   LIMIT)
        if self.actuators.any_tilt_limited:
            self.tilt_rate_limited_steps += 1

    def _check_saturation(self, t_us: int, saturated: bool,
                          omega_sq: tuple[float, ...]) -> None:
        change = self.saturation.update(t_us, saturated, self.settings)
        cmd = self.commander
        if change is SaturationChange.START:
            self.failsafe = Failsafe.ROTOR_SATURATION
            if self.settings.saturation_hold and cmd.mode_ahead == Mode.MISSION and \
                    not cmd.landing_ahead:
                cmd.failsafe_hold("failsafe: rotors saturated: mission aborted, HOLD")
            else:
                speeds = unclamped_speeds(omega_sq)
                which = ",".join(str(i + 1) for i, w in enumerate(speeds)
                                 if w > self.vehicle.rotor_speed_max_rad_s)
                cmd.say(MAV_SEVERITY.MAV_SEVERITY_WARNING,
                        f"rotors saturated for over {self.settings.saturation_s:g} s: {which}",
                        LIMIT)
        elif change is SaturationChange.CLEAR and self.failsafe is Failsafe.ROTOR_SATURATION:
            self.failsafe = Failsafe.NONE

    # ------------------------------------------------------------------ links (wall clock)

    def check_links(self, now_s: float, gcs_seen_s: float = math.inf) -> None:
        """Offboard and MANUAL_CONTROL streams and GCS heartbeat, on the wall clock
        (docs/clocks.md)."""
        cmd = self.commander  # judged by the mode ahead: a change under way (a mission's
        # start braking first) has left the stream's mode as it would have in the loop
        if cmd.armed and cmd.mode_ahead == Mode.OFFBOARD and offboard_lost(
                now_s, cmd.offboard.received_s, cmd.offboard_timeout_s):
            cmd.failsafe_hold("failsafe: offboard setpoints lost: HOLD")
        if cmd.armed and cmd.mode_ahead == Mode.POSCTL and manual_control_lost(
                now_s, cmd.sticks_received_s, cmd.flight.manual_timeout_s):
            cmd.failsafe_hold("failsafe: manual control lost: HOLD")
        change = self.gcs_link.update(now_s, gcs_seen_s, self.settings)
        if change is LinkChange.LOST:
            self.failsafe = Failsafe.GCS_LOST
            if cmd.armed and not cmd.landing_ahead:
                cmd.failsafe_hold("failsafe: GCS link lost: HOLD")
            else:
                cmd.say(MAV_SEVERITY.MAV_SEVERITY_CRITICAL, "failsafe: GCS link lost")
        elif change is LinkChange.LAND and cmd.armed and cmd.mode == Mode.HOLD:
            cmd.failsafe_land("failsafe: GCS link lost: LAND")
        elif change is LinkChange.REGAINED:
            if self.failsafe is Failsafe.GCS_LOST:
                self.failsafe = Failsafe.NONE
            cmd.say(MAV_SEVERITY.MAV_SEVERITY_INFO, "GCS link regained")
