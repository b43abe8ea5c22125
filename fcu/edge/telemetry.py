"""Telemetry of the FCU on its GCS links: message builders (ENU/FLU -> NED/FRD at the wire)
and a wall-clock scheduler whose intervals MAV_CMD_SET_MESSAGE_INTERVAL changes.

Defaults (docs/autopilot.md#telemetry): pose 50 Hz, actuators 10 Hz, status 1 Hz.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.geodetic import ned_to_geodetic
from common.quaternion import zyx_euler, zyx_yaw
from common.wire.identity import FLIGHT_CUSTOM_VERSION
from common.wire.mav_enums import ATTITUDE_TARGET_TYPEMASK, MAV_FRAME, POSITION_TARGET_TYPEMASK
from common.wire.mavlink import MAV
from common.wire.mission_items import HomePosition
from common.wire.modes import MAIN_POSCTL
from common.wire.simlink import pose_covariance
from fcu.estimator.ekf import Estimator
from fcu.pipeline import StepOutput
from fcu.safety.failsafe import Failsafe
from fcu.stages import Reference, VehicleState

M = MAV
DEFAULT_INTERVALS_S: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0.02,
    M.MAVLINK_MSG_ID_ATTITUDE: 0.1,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.02,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    M.MAVLINK_MSG_ID_ODOMETRY: 0.1,
    M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: 0.1,
    M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: 0.02,
    M.MAVLINK_MSG_ID_ATTITUDE_TARGET: 0.02,
    M.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT: 0.1,
    M.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 5.0,
    M.MAVLINK_MSG_ID_ESTIMATOR_STATUS: 1.0,  # only with the estimator (EKF_EN = 1)
}
REQUESTABLE = {*DEFAULT_INTERVALS_S, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION}
CAPABILITIES = (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT)
FLIGHT_SW_VERSION = (0 << 24) | (1 << 16) | (0 << 8) | 255  # 0.1.0, release
MIN_INTERVAL_S = 0.002  # no stream faster than 500 Hz (the loop serves links every 2 ms)
MAX_INTERVAL_US = 2**31 - 1  # MESSAGE_INTERVAL.interval_us is an int32
LINK_BUDGET_MSG_S = 1000.0  # all streams of one link together (defaults: about 264/s)
_PER_SEND = {M.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT: 2}  # builders that send several messages
# The reference's targets: position, velocity, acceleration (no yaw, no yaw rate); attitude
# and body rates (no thrust).
_POSITION_TARGET_MASK = POSITION_TARGET_TYPEMASK.POSITION_TARGET_TYPEMASK_YAW_IGNORE | \
    POSITION_TARGET_TYPEMASK.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
_ATTITUDE_TARGET_MASK = ATTITUDE_TARGET_TYPEMASK.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE


class Snapshot(NamedTuple):
    """What telemetry reports, taken once per send from the pipeline (ENU/FLU inside)."""

    time_us: int
    state: VehicleState | None
    ref: Reference | None
    errors: tuple[float, float] | None  # position error m, attitude error rad
    output: StepOutput | None
    v_enu_m_s: tuple[float, float, float]
    landed: bool
    # None: flying on the exact state input; its status() is taken only by the builders
    # that report it (ODOMETRY, ESTIMATOR_STATUS), not for every snapshot
    estimator: Estimator | None = None
    pose_lost: bool = False  # the estimator dead-reckons beyond COM_POS_LOSS_T


def _i32(x: float) -> int:
    """Rounded and clamped to int32, as the wire's integer fields need."""
    return max(-2**31, min(2**31 - 1, round(x)))


@dataclass
class Schedule:
    """One link's streams: per-message intervals in wall-clock seconds (0 or less = off),
    bounded by the link's budget of messages per second."""

    intervals: dict[int, float]
    due: dict[int, float]
    budget_msg_s: float = LINK_BUDGET_MSG_S

    @classmethod
    def default(cls) -> Schedule:
        return cls(dict(DEFAULT_INTERVALS_S), dict.fromkeys(DEFAULT_INTERVALS_S, 0.0))

    def rate_msg_s(self, intervals: dict[int, float] | None = None) -> float:
        """Messages per second of all streams together."""
        iv = self.intervals if intervals is None else intervals
        return sum(_PER_SEND.get(m, 1) / t for m, t in iv.items() if t > 0)

    def set_interval(self, msg_id: int, interval_us: float) -> tuple[bool, str]:
        """MAV_CMD_SET_MESSAGE_INTERVAL: -1 off, 0 default, > 0 interval in us (at least
        MIN_INTERVAL_S). Refused, with the reason: unknown streams, values MESSAGE_INTERVAL
        cannot carry, and a total beyond the link's budget."""
        if msg_id not in DEFAULT_INTERVALS_S:
            return False, f"no stream for message {msg_id}"
        if not math.isfinite(interval_us) or interval_us > MAX_INTERVAL_US or \
                (interval_us < 0 and interval_us != -1):
            return False, f"interval {interval_us:g} us not -1, 0 or 1..{MAX_INTERVAL_US}"
        trial = dict(self.intervals)
        if interval_us < 0:
            trial[msg_id] = -1.0
        elif interval_us == 0:
            trial[msg_id] = DEFAULT_INTERVALS_S[msg_id]
        else:
            trial[msg_id] = max(round(interval_us) * 1e-6, MIN_INTERVAL_S)
        rate = self.rate_msg_s(trial)
        if rate > self.budget_msg_s and rate > self.rate_msg_s():
            return False, f"link budget {self.budget_msg_s:.0f} msg/s (would be {rate:.0f})"
        self.intervals = trial
        self.due[msg_id] = 0.0
        return True, ""

    def interval_us(self, msg_id: int) -> int:
        """MESSAGE_INTERVAL.interval_us: -1 off, 0 not available, else the interval."""
        if msg_id not in self.intervals:
            return 0
        iv = self.intervals[msg_id]
        return -1 if iv <= 0 else min(round(iv * 1e6), MAX_INTERVAL_US)

    def pop_due(self, now_s: float) -> list[int]:
        out = []
        for msg_id, interval in self.intervals.items():
            if interval > 0 and now_s >= self.due[msg_id]:
                # keep the cadence but never burst after a stall
                self.due[msg_id] = max(self.due[msg_id] + interval, now_s)
                out.append(msg_id)
        return out

    def next_due(self) -> float:
        return min((d for m, d in self.due.items() if self.intervals[m] > 0), default=math.inf)


def heartbeat(armed: bool, custom_mode: int, active: bool, failsafe: str = ""
              ) -> MAV.MAVLink_message:
    """As PX4 sends it: MAV_AUTOPILOT_PX4 with PX4's custom mode (`common.wire.modes`), so that
    pymavlink/MAVProxy, QGroundControl and MAVSDK name the modes and set them by name; base
    mode flags as PX4 sets them (MANUAL_INPUT in POSCTL, AUTO and GUIDED otherwise).
    system_status: ACTIVE/STANDBY, CRITICAL while a failsafe is active, EMERGENCY after a
    divergence (as PX4 reports failsafes)."""
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
    base |= M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
    if (custom_mode >> 16) & 0xFF == MAIN_POSCTL:
        base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    else:
        base |= M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_AUTO_ENABLED
    status = M.MAV_STATE_ACTIVE if active else M.MAV_STATE_STANDBY
    if failsafe:
        status = M.MAV_STATE_EMERGENCY if failsafe == Failsafe.DIVERGED else M.MAV_STATE_CRITICAL
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_HEXAROTOR, M.MAV_AUTOPILOT_PX4, base,
                                       custom_mode, status, 3)


def autopilot_version(uid: int) -> MAV.MAVLink_message:
    """AUTOPILOT_VERSION with this FCU's tag in flight_custom_version (`common.wire.identity`:
    it flies position and attitude targets together)."""
    return M.MAVLink_autopilot_version_message(
        CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, list(FLIGHT_CUSTOM_VERSION), [0] * 8,
        [0] * 8, 0, 0, uid, [0] * 18)


# What the simulated vehicle has (SYS_STATUS `present`): the plant's IMU and barometer
# (HIL_SENSOR: gyro, accelerometer, absolute pressure; no magnetometer, no GNSS), and the
# external pose the FCU flies on (ODOMETRY, as from motion capture: VISION_POSITION, and the
# attitude estimate AHRS); the controllers, the rotor outputs, the pre-arm check.
STATE_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                 | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
                 | M.MAV_SYS_STATUS_SENSOR_VISION_POSITION | M.MAV_SYS_STATUS_AHRS)
CONTROLLERS = (M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
               | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
               | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
               | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
               | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
               | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
NO_BATTERY = (65535, -1, -1)  # voltage_battery (UINT16_MAX), current_battery, remaining: not
# measured (MAVLink's values for "unknown"); no BATTERY_STATUS is sent: no battery is simulated


def sys_status(*, state_ok: bool, control_ok: bool, prearm_ok: bool,
               manual_control: bool | None, load_permille: int, rejected: int,
               signing_rejects: int) -> MAV.MAVLink_message:
    """Sensor bits that tell the truth: `present` what the simulated vehicle has (above),
    `enabled` the same, `health` what works now: the state sensors while the state input
    arrives (`state_ok`), the controllers unless a failsafe is active (`control_ok`),
    PREARM_CHECK when arming would be accepted (`prearm_ok`; MAVSDK's is_armable),
    RC_RECEIVER present once MANUAL_CONTROL has been heard (`manual_control` not None) and
    healthy while it is fresh. Absent sensors are not healthy, except GEOFENCE, whose health
    bit ground stations read as "no breach" (MAVProxy prints "fence breach" when it is
    clear): no fence is monitored here, so none is breached. errors_comm = rejected input
    (bytes and messages), errors_count1 = frames refused by MAVLink signing. Battery: not
    measured (NO_BATTERY)."""
    present = STATE_SENSORS | CONTROLLERS | M.MAV_SYS_STATUS_PREARM_CHECK
    health = M.MAV_SYS_STATUS_GEOFENCE
    health |= STATE_SENSORS if state_ok else 0
    health |= CONTROLLERS if control_ok else 0
    health |= M.MAV_SYS_STATUS_PREARM_CHECK if prearm_ok else 0
    if manual_control is not None:
        present |= M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
        health |= M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER if manual_control else 0
    voltage, current, remaining = NO_BATTERY
    return M.MAVLink_sys_status_message(
        present, present, health, min(load_permille, 1000), voltage, current, remaining,
        0, min(rejected, 65535), min(signing_rejects, 65535), 0, 0, 0, 0, 0, 0)


class Builders:
    """Telemetry messages from the FCU's latest state; `get` maps a message id to a builder."""

    def __init__(self, source: Callable[[], Snapshot], home: HomePosition) -> None:
        self.source = source
        self.home = home

    def build(self, msg_id: int) -> MAV.MAVLink_message | list[MAV.MAVLink_message] | None:
        fn = self._table().get(msg_id)
        return fn(self.source()) if fn else None

    def _table(self) -> dict[int, Callable[[Snapshot], object]]:
        return {
            M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self.attitude_quaternion,
            M.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position,
            M.MAVLINK_MSG_ID_ODOMETRY: self.odometry,
            M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: self.actuators,
            M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: self.position_target,
            M.MAVLINK_MSG_ID_ATTITUDE_TARGET: self.attitude_target,
            M.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT: self.errors,
            M.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            M.MAVLINK_MSG_ID_ESTIMATOR_STATUS: self.estimator_status,
        }

    @staticmethod
    def _ms(src: Snapshot) -> int:
        return int(src.time_us // 1000) & 0xFFFFFFFF

    def attitude_quaternion(self, src: Snapshot) -> MAV.MAVLink_message | None:
        s = src.state
        if s is None:
            return None
        q = q_enu_flu_to_ned_frd(s.q_enu_flu)
        w = flu_to_frd(s.omega_flu_rad_s)
        return M.MAVLink_attitude_quaternion_message(self._ms(src), *q, *w, [0.0] * 4)

    def attitude(self, src: Snapshot) -> MAV.MAVLink_message | None:
        s = src.state
        if s is None:
            return None
        roll, pitch, yaw = zyx_euler(q_enu_flu_to_ned_frd(s.q_enu_flu))
        rates = flu_to_frd(s.omega_flu_rad_s)
        return M.MAVLink_attitude_message(self._ms(src), roll, pitch, yaw, *rates)

    def local_position(self, src: Snapshot) -> MAV.MAVLink_message | None:
        s = src.state
        if s is None:
            return None
        return M.MAVLink_local_position_ned_message(self._ms(src), *enu_to_ned(s.p_enu_m),
                                                    *enu_to_ned(src.v_enu_m_s))

    def global_position(self, src: Snapshot) -> MAV.MAVLink_message | None:
        s = src.state
        if s is None:
            return None
        p_ned = enu_to_ned(s.p_enu_m)
        lat, lon, alt = ned_to_geodetic(p_ned, self.home.lat_deg, self.home.lon_deg,
                                        self.home.alt_m)
        v = enu_to_ned(src.v_enu_m_s)
        yaw = zyx_yaw(q_enu_flu_to_ned_frd(s.q_enu_flu))
        hdg = round(math.degrees(yaw) % 360.0 * 100) % 36000
        return M.MAVLink_global_position_int_message(
            self._ms(src), _i32(lat * 1e7), _i32(lon * 1e7), _i32(alt * 1000),
            _i32(-p_ned[2] * 1000), *(max(-32768, min(32767, round(c * 100))) for c in v), hdg)

    def odometry(self, src: Snapshot) -> MAV.MAVLink_message | None:
        """The state the FCU flies on: the estimate (estimator_type AUTOPILOT, with its
        pose and velocity variances) or the external state passed through (MOCAP)."""
        s = src.state
        if s is None:
            return None
        est = src.estimator.status() if src.estimator is not None else None
        pose_cov = [math.nan] + [0.0] * 20
        vel_cov = [math.nan] + [0.0] * 20
        kind = M.MAV_ESTIMATOR_TYPE_MOCAP
        if est is not None:
            kind = M.MAV_ESTIMATOR_TYPE_AUTOPILOT
            pn, pe, pd = (est.pos_sd_m[1], est.pos_sd_m[0], est.pos_sd_m[2])  # ENU -> NED
            ax, ay, az = est.att_sd_rad[0], -est.att_sd_rad[1], -est.att_sd_rad[2]
            pose_cov = list(pose_covariance(0.0, 0.0))
            for i, sd in zip((0, 6, 11, 15, 18, 20), (pn, pe, pd, ax, ay, az), strict=True):
                pose_cov[i] = sd * sd
            vel_cov = [0.0] * 21
            ve, vn, vu = est.vel_sd_m_s
            for i, sd in zip((0, 6, 11), (vn, ve, vu), strict=True):
                vel_cov[i] = sd * sd
            vel_cov[15] = math.nan  # rates: not estimated (bias-corrected gyro)
        return M.MAVLink_odometry_message(
            src.time_us, M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_BODY_FRD, *enu_to_ned(s.p_enu_m),
            q_enu_flu_to_ned_frd(s.q_enu_flu), *flu_to_frd(s.v_flu_m_s),
            *flu_to_frd(s.omega_flu_rad_s), pose_cov, vel_cov, 0, kind, 100)

    def estimator_status(self, src: Snapshot) -> MAV.MAVLink_message | None:
        """ESTIMATOR_STATUS as PX4 fills it: solution flags, test ratios (pose position in
        pos_horiz/vert_ratio, pose attitude in mag_ratio: the heading aid), accuracies."""
        est = src.estimator.status() if src.estimator is not None else None
        if est is None:
            return None
        flags = 0
        if est.aligned and est.healthy:
            flags = (M.ESTIMATOR_ATTITUDE | M.ESTIMATOR_VELOCITY_HORIZ
                     | M.ESTIMATOR_VELOCITY_VERT | M.ESTIMATOR_PRED_POS_HORIZ_REL)
            if not src.pose_lost:
                flags |= M.ESTIMATOR_POS_HORIZ_REL | M.ESTIMATOR_POS_VERT_ABS
        if not est.healthy:
            flags |= M.ESTIMATOR_ACCEL_ERROR
        sx, sy, sz = est.pos_sd_m
        return M.MAVLink_estimator_status_message(
            src.time_us, flags, 0.0, est.pos_test_ratio, est.pos_test_ratio,
            est.att_test_ratio, 0.0, 0.0, math.hypot(sx, sy), sz)

    def actuators(self, src: Snapshot) -> MAV.MAVLink_message | None:
        out = src.output
        if out is None:
            return None
        values = [*out.speed_rad_s, *out.tilt_rad]
        return M.MAVLink_actuator_output_status_message(
            src.time_us, (1 << len(values)) - 1, values + [0.0] * (32 - len(values)))

    def position_target(self, src: Snapshot) -> MAV.MAVLink_message | None:
        ref = src.ref
        if ref is None:
            return None
        return M.MAVLink_position_target_local_ned_message(
            self._ms(src), MAV_FRAME.MAV_FRAME_LOCAL_NED, _POSITION_TARGET_MASK,
            *enu_to_ned(ref.p_enu_m), *enu_to_ned(ref.v_enu_m_s), *enu_to_ned(ref.a_enu_m_s2),
            0.0, 0.0)

    def attitude_target(self, src: Snapshot) -> MAV.MAVLink_message | None:
        ref = src.ref
        if ref is None:
            return None
        return M.MAVLink_attitude_target_message(
            self._ms(src), _ATTITUDE_TARGET_MASK, q_enu_flu_to_ned_frd(ref.q_enu_flu),
            *flu_to_frd(ref.omega_flu_rad_s), 0.0)

    def errors(self, src: Snapshot) -> list[MAV.MAVLink_message] | None:
        errs = src.errors
        if errs is None:
            return None
        ms = self._ms(src)
        return [M.MAVLink_named_value_float_message(ms, b"ERR_POS", errs[0]),
                M.MAVLink_named_value_float_message(ms, b"ERR_ATT", errs[1])]

    def home_position(self, src: Snapshot) -> MAV.MAVLink_message:
        h = self.home
        return M.MAVLink_home_position_message(
            round(h.lat_deg * 1e7), round(h.lon_deg * 1e7), round(h.alt_m * 1000), 0.0, 0.0,
            0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, src.time_us)

    def extended_sys_state(self, src: Snapshot) -> MAV.MAVLink_message:
        landed = (M.MAV_LANDED_STATE_ON_GROUND if src.landed
                  else M.MAV_LANDED_STATE_IN_AIR)
        return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED, landed)
