"""The FCU's onboard log (`onboard.ulg`): what the flight controller saw, wanted and sent.

Topics (ULog, read with pyulog); PX4's layouts are in `common.logs.px4_topics`:

- `dq_onboard`, every control step in flight: ONBOARD_COLUMNS in float64, ENU/FLU (state,
  desired pose and twist, wrench, commands, raw and unwrapped tilts, dual-quaternion errors,
  step time), and `state_time_us`, the simulator's stamp of the control period the step
  answered: the state's as its source sent it, or with the estimator the IMU sample at the
  period's end, where the estimate is taken (`Pipeline.period_stamp_us`; in real time a
  newer sample may have come before the step): the key that joins it to truth.ulg
  (`gcs.run.runio`); every metric of the controller's side is computed from it.
- At PX4_HZ (NED/FRD, float32): vehicle_local_position, vehicle_attitude,
  vehicle_angular_velocity (the state the controller used); in flight trajectory_setpoint,
  vehicle_local_position_setpoint, vehicle_attitude_setpoint, vehicle_rates_setpoint (the
  reference); actuator_motors (speed / limit), actuator_servos (tilt wrapped to [-pi, pi),
  divided by pi), control_allocator_status (rotors at their limits).
- At STATUS_HZ and at every change: vehicle_status, failsafe_flags, mission_result.
- With the estimator on (EKF_EN = 1; declared always, empty otherwise): every input the
  estimator received, in the order it received them: `sensor_combined` (each IMU sample,
  FRD, the HIL_SENSOR's float32 values, timestamp = the sample's time) and
  `vehicle_visual_odometry` (each external pose: timestamp = when it was received, on the
  IMU clock: the time of the IMU sample it arrived before, as the simulator sends a pose
  before the IMU sample of the same instant; timestamp_sample = its capture time; the
  values `fcu.edge.sim_bridge.pose_from_odometry` produced, in NED as on the wire, from which
  the conversion to ENU gives them back exactly). A replay (`gcs replay`) that merges the
  two by timestamp, a pose before the IMU sample of the same timestamp, feeds the
  estimator what the FCU fed it. At PX4_HZ: `estimator_status`, and once aligned
  `estimator_states` (the output state at the newest IMU sample, EKF2's order),
  `estimator_innovations` and `estimator_innovation_test_ratios` (of the last pose).
  With the first input, two information messages give what the replay needs beyond the
  parameters: `dq_gravity_m_s2` (the estimator's gravity, as text: exact) and
  `dq_control_period_us` (the estimate is taken at IMU samples on multiples of it).

One clock per log (docs/clocks.md): every timestamp is the FCU's flight clock. In lockstep
the simulator's stamps are that clock; in real time they come from another process's clock,
and the stamps of samples (states, IMU samples, poses, the estimate) are moved onto the
flight clock by `clock_offset_us`, set once from the first sample (a whole number of
control periods, so samples on period multiples stay on them).

Parameters are in the definitions (their values when the log opened, with MAV_TYPE,
MAV_SYS_ID and SYS_AUTOSTART: `identity_params`) and as changes in the data; everything the
vehicle says (events and STATUSTEXT) is a logged string at its flight time. The same logger
runs in the FCU process and in the in-process runner.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from common.logs import px4_topics as px4
from common.logs.columns import ONBOARD_COLUMNS
from common.logs.ulog import Topic, ULogWriter, info_message
from common.outcome import Event
from common.quaternion import q_rotate
from common.wire.mission_items import PX4_SITL_HOME, HomePosition
from common.wire.modes import Mode
from fcu.control.core import onboard_row
from fcu.estimator.inputs import ImuInput, PoseInput
from fcu.pipeline import Pipeline, StepOutput
from fcu.safety.failsafe import CRITICAL_FAILSAFES, Failsafe, state_lost

# dq_onboard's columns as read back (`common.logs.ulog.read_topic`): ONBOARD_COLUMNS, then the
# stamp of the state each step acted on
DQ_ONBOARD_COLUMNS = (*ONBOARD_COLUMNS, "state_time_us")
DQ_ONBOARD = Topic("dq_onboard", (("uint64_t", "timestamp"),
                                  *(("double", c) for c in ONBOARD_COLUMNS[1:]),
                                  ("uint64_t", "state_time_us")))
ONBOARD_TOPICS = (
    DQ_ONBOARD, px4.VEHICLE_LOCAL_POSITION, px4.VEHICLE_ATTITUDE, px4.VEHICLE_ANGULAR_VELOCITY,
    px4.TRAJECTORY_SETPOINT, px4.VEHICLE_LOCAL_POSITION_SETPOINT,
    px4.VEHICLE_ATTITUDE_SETPOINT, px4.VEHICLE_RATES_SETPOINT, px4.ACTUATOR_MOTORS,
    px4.ACTUATOR_SERVOS, px4.CONTROL_ALLOCATOR_STATUS, px4.VEHICLE_STATUS,
    px4.FAILSAFE_FLAGS, px4.MISSION_RESULT, *px4.ESTIMATOR_TOPICS)
PX4_HZ = 50
STATUS_HZ = 2
MAV_TYPE_HEXAROTOR = 13
NAV_STATE = {Mode.HOLD: px4.NAVIGATION_STATE_AUTO_LOITER,
             Mode.MISSION: px4.NAVIGATION_STATE_AUTO_MISSION,
             Mode.OFFBOARD: px4.NAVIGATION_STATE_OFFBOARD,
             Mode.LAND: px4.NAVIGATION_STATE_AUTO_LAND,
             Mode.TAKEOFF: px4.NAVIGATION_STATE_AUTO_TAKEOFF,
             Mode.RTL: px4.NAVIGATION_STATE_AUTO_RTL,
             Mode.POSCTL: px4.NAVIGATION_STATE_POSCTL}
def identity_params(system_id: int) -> dict[str, int]:
    """The int32 parameters a PX4 log carries that Flight Review and pyulog read for what
    the vehicle is: MAV_TYPE (`PX4ULog.get_mav_type`: "Hexarotor"), MAV_SYS_ID, and
    SYS_AUTOSTART 0 (no PX4 airframe: none describes a tilt-rotor hexarotor)."""
    return {"MAV_TYPE": MAV_TYPE_HEXAROTOR, "MAV_SYS_ID": system_id, "SYS_AUTOSTART": 0}


class OnboardLog(ULogWriter):
    """Append-only onboard log of a pipeline; `step` after each control step, `flush` after
    it (the process) or whenever convenient (in-process)."""

    def __init__(self, sink: str | Path | bytearray, pipeline: Pipeline,
                 params: Mapping[str, float], *, system_id: int = 1,
                 home: HomePosition | None = None) -> None:
        self.pipeline = pipeline
        self.system_id = system_id
        self.w_max = pipeline.vehicle.rotor_speed_max_rad_s
        # ref_timestamp, ref_lat, ref_lon, ref_alt of the local frame's origin (the home)
        home = home or PX4_SITL_HOME  # the FCU's default home
        self.ref_origin = (0, home.lat_deg, home.lon_deg, home.alt_m)
        self.params = dict(params)
        super().__init__(sink, ONBOARD_TOPICS, info={
            "sys_name": "dqflight", "ver_hw": "SITL", "ver_sw": "0.1.0",
            "sys_mcu": "python", "sys_toolchain": "CPython"},
            params={**self.params, **identity_params(system_id)})
        self.px4_period_us = 1_000_000 // PX4_HZ
        self.status_period_us = 1_000_000 // STATUS_HZ
        self.next_px4_us = 0
        self.next_status_us = 0
        self.last_status: tuple[object, ...] = ()
        self.armed_time_us = 0
        self.takeoff_time_us = 0
        self.nav_state_since_us = 0
        self.last_nav_state = -1
        self.seq_reached = -1
        self._sensor_combined = self._ids["sensor_combined"]  # packed in `_imu`
        self._dq_onboard = self._ids[DQ_ONBOARD.name]  # packed in `step`
        pipeline.estimator_inputs = []  # the pipeline keeps the estimator's inputs for us
        self.estimator_info_logged = False
        self.imu_t_us = -1  # the newest IMU sample logged
        self.imu_dt_us = 0
        self.poses_waiting: list[PoseInput] = []  # received after it: stamped with the next
        # source (simulator) clock -> flight clock, for sample stamps; 0 in lockstep
        self.clock_offset_us = 0
        self.clock_offset_set = False

    # ------------------------------------------------------------------ records

    def set_source_clock(self, stamp_us: int, flight_us: int) -> None:
        """Real time: a sample stamped `stamp_us` by its source arrived at `flight_us` of the
        flight clock; from the first call on, sample stamps are logged on the flight clock
        (moved by a whole number of control periods). Later calls change nothing."""
        if self.clock_offset_set:
            return
        self.clock_offset_set = True
        period = self.pipeline.period_us
        self.clock_offset_us = round((flight_us - stamp_us) / period) * period

    def on_flight_clock(self, stamp_us: int) -> int:
        """A source's sample stamp on the flight clock (never before its start)."""
        return max(stamp_us + self.clock_offset_us, 0)

    def step(self, out: StepOutput, step_us: float, t_us: int,
             row: tuple[float, ...] | None = None) -> None:
        """Queue the records of one control step at flight time t_us; `row`: its
        `onboard_row` when the caller made it already (its stamp is not read)."""
        pipe = self.pipeline
        state = pipe.state
        self._estimator_inputs()
        if out.result is not None and state is not None:
            stamp_us = pipe.period_stamp_us  # the period answered (out.t_us: newest sample)
            if row is None:
                row = onboard_row(stamp_us, state, out.result, out.speed_rad_s, out.tilt_rad,
                                  out.armed, step_us)
            msg_id, record = self._dq_onboard  # (stamp, row[1:], state_time_us) packed
            self._pending.append(record.pack(record.size - 3, 68, msg_id,
                                             self.on_flight_clock(stamp_us), *row[1:],
                                             stamp_us))
        if t_us >= self.next_px4_us:
            self.next_px4_us = (t_us // self.px4_period_us + 1) * self.px4_period_us
            self._px4(out, t_us)
        self._status(t_us)

    def _px4(self, out: StepOutput, t_us: int) -> None:
        pipe = self.pipeline
        state = pipe.state
        w = self
        # timestamp_sample: the period the step answered
        stamp = self.on_flight_clock(pipe.period_stamp_us if state is not None else out.t_us)
        if state is not None:
            valid = not state_lost(t_us, pipe.state_rx_us, pipe.settings)
            v_enu = q_rotate(state.q_enu_flu, state.v_flu_m_s)
            w.add("vehicle_local_position", px4.local_position_record(
                t_us, stamp, state.p_enu_m, v_enu, state.q_enu_flu, valid, self.ref_origin))
            w.add("vehicle_attitude", px4.attitude_record(t_us, stamp, state.q_enu_flu))
            w.add("vehicle_angular_velocity",
                  px4.angular_velocity_record(t_us, stamp, state.omega_flu_rad_s))
        if out.result is not None:
            r = out.result.reference
            motion = (r.p_enu_m, r.v_enu_m_s, r.a_enu_m_s2, r.q_enu_flu, r.omega_flu_rad_s)
            w.add("trajectory_setpoint", px4.trajectory_setpoint_record(t_us, *motion))
            w.add("vehicle_local_position_setpoint",
                  px4.local_position_setpoint_record(t_us, *motion))
            w.add("vehicle_attitude_setpoint",
                  px4.attitude_setpoint_record(t_us, r.q_enu_flu, r.omega_flu_rad_s))
            w.add("vehicle_rates_setpoint", px4.rates_setpoint_record(t_us, r.omega_flu_rad_s))
        w.add("actuator_motors", px4.actuator_motors_record(t_us, stamp, out.speed_rad_s,
                                                            self.w_max, out.armed))
        w.add("actuator_servos", px4.actuator_servos_record(t_us, stamp, out.tilt_rad))
        saturated = out.result is not None and out.result.allocation.saturated
        w.add("control_allocator_status", px4.control_allocator_status_record(
            t_us, out.speed_rad_s, self.w_max, out.armed, saturated))
        if pipe.estimator is not None:
            self._estimator(t_us)

    def _estimator_inputs(self) -> None:
        """sensor_combined and vehicle_visual_odometry records of the inputs the pipeline
        handed to the estimator since the last call (a pose waits for the next IMU sample,
        whose time is its timestamp)."""
        pipe = self.pipeline
        inputs = pipe.estimator_inputs
        if not inputs:
            return
        if not self.estimator_info_logged and pipe.estimator is not None:
            self.estimator_info_logged = True
            gravity = pipe.estimator.settings.gravity_m_s2
            self._pending.append(info_message("dq_gravity_m_s2", repr(gravity)))
            self._pending.append(info_message("dq_control_period_us", pipe.period_us))
        for m in inputs:
            if type(m) is ImuInput:
                self._imu(m)
            elif isinstance(m, PoseInput):
                self.poses_waiting.append(m)
            elif isinstance(m, ImuInput):
                self._imu(m)
        inputs.clear()

    def _imu(self, m: ImuInput) -> None:
        """sensor_combined of one IMU sample (`px4.sensor_combined_record`, packed here),
        after the poses received before it."""
        t = m.t_us + self.clock_offset_us  # on_flight_clock
        if t < 0:
            t = 0
        if self.imu_t_us >= 0:
            d = t - self.imu_t_us
            self.imu_dt_us = 0 if d < 0 else min(d, 0xFFFFFFFF)
        if self.poses_waiting:
            for pose in self.poses_waiting:
                self._pose(t, pose)
            self.poses_waiting.clear()
        w, f, dt = m.omega_flu_rad_s, m.f_flu_m_s2, self.imu_dt_us
        msg_id, record = self._sensor_combined
        self._pending.append(record.pack(record.size - 3, 68, msg_id, t, w[0], -w[1], -w[2],
                                         dt, 0, f[0], -f[1], -f[2], dt))
        self.imu_t_us = t

    def _pose(self, rx_us: int, m: PoseInput) -> None:
        self.add("vehicle_visual_odometry", px4.visual_odometry_record(
            rx_us, self.on_flight_clock(m.capture_us), m.p_enu_m, m.q_enu_flu, m.pos_var_m2,
            m.att_var_rad2))

    def _estimator(self, t_us: int) -> None:
        """The estimator's state, innovations, test ratios and status at flight time t_us."""
        pipe = self.pipeline
        est = pipe.estimator
        assert est is not None
        st = est.status()
        stamp = self.on_flight_clock(max(st.t_us, 0))
        w = self
        if st.aligned:
            out = est.output()
            if out is not None:
                s = out[1]
                w.add("estimator_states", px4.estimator_states_record(
                    t_us, stamp, s.p_enu_m, q_rotate(s.q_enu_flu, s.v_flu_m_s), s.q_enu_flu,
                    st.gyro_bias_rad_s, st.accel_bias_m_s2, est.covariance.diagonal().tolist()))
                w.add("estimator_innovations", px4.estimator_innovations_record(
                    t_us, stamp, st.pos_innov_m, st.att_innov_rad, s.q_enu_flu))
                w.add("estimator_innovation_test_ratios", px4.estimator_test_ratios_record(
                    t_us, stamp, st.pos_test_ratio, st.att_test_ratio))
        w.add("estimator_status", px4.estimator_status_record(
            t_us, stamp, aligned=st.aligned, healthy=st.healthy,
            in_air=not pipe.commander.landed, dead_reckoning=pipe.pose_level > 0,
            pos_sd_enu_m=st.pos_sd_m, pos_ratio=st.pos_test_ratio,
            att_ratio=st.att_test_ratio))

    def _status(self, t_us: int) -> None:
        pipe = self.pipeline
        cmd = pipe.commander
        nav_state = NAV_STATE[cmd.mode]
        if nav_state != self.last_nav_state:
            self.last_nav_state = nav_state
            self.nav_state_since_us = t_us
        if cmd.armed and not self.armed_time_us:
            self.armed_time_us = max(t_us, 1)
        elif not cmd.armed:
            self.armed_time_us = 0
        if cmd.armed and not cmd.landed and not self.takeoff_time_us:
            self.takeoff_time_us = max(t_us, 1)
        elif not cmd.armed:
            self.takeoff_time_us = 0
        for ev in cmd.mission_events:
            if ev.kind == "reached":
                self.seq_reached = max(self.seq_reached, ev.seq)
        lost = pipe.state is not None and state_lost(t_us, pipe.state_rx_us, pipe.settings)
        key = (cmd.armed, nav_state, pipe.failsafe, lost, bool(cmd.mission),
               cmd.mission_current, self.seq_reached, cmd.mission_done, self.takeoff_time_us)
        if key == self.last_status and t_us < self.next_status_us:
            return
        self.last_status = key
        self.next_status_us = (t_us // self.status_period_us + 1) * self.status_period_us
        w = self
        gcs_lost = pipe.failsafe == Failsafe.GCS_LOST
        w.add("vehicle_status", (
            t_us, self.armed_time_us, self.takeoff_time_us,
            px4.ARMING_STATE_ARMED if cmd.armed else px4.ARMING_STATE_DISARMED,
            self.nav_state_since_us, nav_state, nav_state, px4.HIL_STATE_OFF,
            px4.VEHICLE_TYPE_ROTARY_WING, bool(pipe.failsafe), False, gcs_lost,
            MAV_TYPE_HEXAROTOR, self.system_id, 1))
        w.add("failsafe_flags", (t_us, lost, lost, lost, lost, lost, not cmd.mission, gcs_lost,
                                 pipe.failsafe in CRITICAL_FAILSAFES))
        w.add("mission_result", (t_us, self.seq_reached, cmd.mission_current,
                                 len(cmd.mission), bool(cmd.mission), cmd.mission_done))

    def close(self, beside: bool = False) -> None:
        """The estimator's last inputs (poses after the last IMU sample stamped with the time
        the next one was due), then the file closed (`ULogWriter.close`)."""
        self._estimator_inputs()
        for pose in self.poses_waiting:
            self._pose(max(self.imu_t_us + self.imu_dt_us, 0), pose)
        self.poses_waiting.clear()
        super().close(beside)

    def events(self, events: list[Event]) -> None:
        for ev in events:
            self.log(ev.t_us, ev.severity, ev.text)

    def set_params(self, values: Mapping[str, float]) -> None:
        """Log the parameters that changed since the last call."""
        for name, value in values.items():
            if self.params.get(name) != value:
                self.params[name] = value
                self.param(name, value)


def set_aside(path: Path) -> Path | None:
    """Where a finished log still at `path` is moved before a new one starts there (log
    rotation: a log already renamed stays as it is): the first free `name.N.ulg`; None when
    there is nothing at `path`."""
    if not path.exists():
        return None
    n = 1
    while (aside := path.with_name(f"{path.stem}.{n}{path.suffix}")).exists():
        n += 1
    path.rename(aside)
    return aside
