"""PX4's uORB message layouts for the ULog logs: names, fields, types and frames as PX4
defines them (msg/*.msg, v1.15), so Flight Review, PlotJuggler and pyulog scripts written
for PX4 logs read ours.

Only the fields this vehicle has a value for are declared (a ULog format names its fields,
so a reader looks them up by name). PX4 conventions: float32, local frame NED, body frame
FRD, quaternions Hamilton [w, x, y, z] rotating FRD into NED, timestamps in microseconds.
What PX4 has no topic for, and the float64 values the metrics need, are in the project's
own topics (`dq_truth` in sitl.truth_log, `dq_onboard` in fcu.edge.onboard_log).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

import numpy as np

from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd, q_ned_frd_to_enu_flu
from common.logs.ulog import Topic
from common.quaternion import Quat, Vec3, q_rotate, zyx_yaw
from common.wire.rounding import f32_quat

_T = ("uint64_t", "timestamp")
_TS = ("uint64_t", "timestamp_sample")


def _local_position(name: str) -> Topic:
    return Topic(name, (
        _T, _TS, ("bool", "xy_valid"), ("bool", "z_valid"), ("bool", "v_xy_valid"),
        ("bool", "v_z_valid"), ("float", "x"), ("float", "y"), ("float", "z"),
        ("float", "vx"), ("float", "vy"), ("float", "vz"), ("float", "heading"),
        ("bool", "xy_global"), ("bool", "z_global"), ("uint64_t", "ref_timestamp"),
        ("double", "ref_lat"), ("double", "ref_lon"), ("float", "ref_alt")))


def _attitude(name: str) -> Topic:
    return Topic(name, (_T, _TS, ("float", "q", 4), ("float", "delta_q_reset", 4),
                        ("uint8_t", "quat_reset_counter")))


def _angular_velocity(name: str) -> Topic:
    return Topic(name, (_T, _TS, ("float", "xyz", 3)))


VEHICLE_LOCAL_POSITION = _local_position("vehicle_local_position")
VEHICLE_ATTITUDE = _attitude("vehicle_attitude")
VEHICLE_ANGULAR_VELOCITY = _angular_velocity("vehicle_angular_velocity")
# Ground truth as PX4 SITL logs it: the same layouts under *_groundtruth.
VEHICLE_LOCAL_POSITION_GROUNDTRUTH = _local_position("vehicle_local_position_groundtruth")
VEHICLE_ATTITUDE_GROUNDTRUTH = _attitude("vehicle_attitude_groundtruth")
VEHICLE_ANGULAR_VELOCITY_GROUNDTRUTH = _angular_velocity(
    "vehicle_angular_velocity_groundtruth")

TRAJECTORY_SETPOINT = Topic("trajectory_setpoint", (
    _T, ("float", "position", 3), ("float", "velocity", 3), ("float", "acceleration", 3),
    ("float", "jerk", 3), ("float", "yaw"), ("float", "yawspeed")))
VEHICLE_LOCAL_POSITION_SETPOINT = Topic("vehicle_local_position_setpoint", (
    _T, ("float", "x"), ("float", "y"), ("float", "z"), ("float", "vx"), ("float", "vy"),
    ("float", "vz"), ("float", "acceleration", 3), ("float", "yaw"), ("float", "yawspeed")))
VEHICLE_ATTITUDE_SETPOINT = Topic("vehicle_attitude_setpoint", (
    _T, ("float", "yaw_sp_move_rate"), ("float", "q_d", 4), ("bool", "reset_integral")))
VEHICLE_RATES_SETPOINT = Topic("vehicle_rates_setpoint", (
    _T, ("float", "roll"), ("float", "pitch"), ("float", "yaw"), ("bool", "reset_integral")))

# Normalised outputs: motors 0..1 of the rotor speed limit, servos -1..1 (PX4's ranges).
ACTUATOR_MOTORS = Topic("actuator_motors", (
    _T, _TS, ("uint16_t", "reversible_flags"), ("float", "control", 12)))
ACTUATOR_SERVOS = Topic("actuator_servos", (_T, _TS, ("float", "control", 8)))
CONTROL_ALLOCATOR_STATUS = Topic("control_allocator_status", (
    _T, ("bool", "torque_setpoint_achieved"), ("bool", "thrust_setpoint_achieved"),
    ("int8_t", "actuator_saturation", 16), ("uint16_t", "handled_motor_failure_mask")))
ACTUATOR_SATURATION_UPPER = 2
ACTUATOR_SATURATION_LOWER = -2

VEHICLE_STATUS = Topic("vehicle_status", (
    _T, ("uint64_t", "armed_time"), ("uint64_t", "takeoff_time"),
    ("uint8_t", "arming_state"), ("uint64_t", "nav_state_timestamp"),
    ("uint8_t", "nav_state_user_intention"), ("uint8_t", "nav_state"),
    ("uint8_t", "hil_state"), ("uint8_t", "vehicle_type"), ("bool", "failsafe"),
    ("bool", "failsafe_and_user_took_over"), ("bool", "gcs_connection_lost"),
    ("uint8_t", "system_type"), ("uint8_t", "system_id"), ("uint8_t", "component_id")))
ARMING_STATE_DISARMED, ARMING_STATE_ARMED = 1, 2
HIL_STATE_OFF = 0  # SITL, not hardware in the loop (PX4's SYS_HITL = 0)
VEHICLE_TYPE_ROTARY_WING = 1
# nav_state values (vehicle_status.msg)
NAVIGATION_STATE_POSCTL = 2
NAVIGATION_STATE_AUTO_MISSION = 3
NAVIGATION_STATE_AUTO_LOITER = 4
NAVIGATION_STATE_AUTO_RTL = 5
NAVIGATION_STATE_OFFBOARD = 14
NAVIGATION_STATE_AUTO_TAKEOFF = 17
NAVIGATION_STATE_AUTO_LAND = 18

FAILSAFE_FLAGS = Topic("failsafe_flags", (
    _T, ("bool", "angular_velocity_invalid"), ("bool", "attitude_invalid"),
    ("bool", "local_altitude_invalid"), ("bool", "local_position_invalid"),
    ("bool", "local_velocity_invalid"), ("bool", "auto_mission_missing"),
    ("bool", "gcs_connection_lost"), ("bool", "fd_critical_failure")))

MISSION_RESULT = Topic("mission_result", (
    _T, ("int32_t", "seq_reached"), ("uint16_t", "seq_current"), ("uint16_t", "seq_total"),
    ("bool", "valid"), ("bool", "finished")))


# ---------------------------------------------------------------------------------------------
# Records: the one conversion from the code's ENU/FLU values to these topics' NED/FRD fields
# ---------------------------------------------------------------------------------------------

def local_position_record(t_us: int, stamp_us: int, p_enu_m: Vec3, v_enu_m_s: Vec3,
                          q_enu_flu: Quat, valid: bool,
                          ref: tuple[int, float, float, float] | None
                          ) -> tuple[float | int | bool, ...]:
    """vehicle_local_position[_groundtruth]: NED position, velocity and heading; `ref` is
    (ref_timestamp, ref_lat, ref_lon, ref_alt) of the local frame's origin, None when the
    origin has no global position (xy_global and z_global false)."""
    origin = ref is not None
    return (t_us, stamp_us, valid, valid, valid, valid, *enu_to_ned(p_enu_m),
            *enu_to_ned(v_enu_m_s), zyx_yaw(q_enu_flu_to_ned_frd(q_enu_flu)), origin, origin,
            *(ref if ref is not None else (0, 0.0, 0.0, 0.0)))


def attitude_record(t_us: int, stamp_us: int, q_enu_flu: Quat
                    ) -> tuple[float | int, ...]:
    """vehicle_attitude[_groundtruth]: q rotating FRD into NED, no resets."""
    return (t_us, stamp_us, *q_enu_flu_to_ned_frd(q_enu_flu), 0.0, 0.0, 0.0, 0.0, 0)


def angular_velocity_record(t_us: int, stamp_us: int, omega_flu_rad_s: Vec3
                            ) -> tuple[float | int, ...]:
    """vehicle_angular_velocity[_groundtruth]: body rate in FRD."""
    return (t_us, stamp_us, *flu_to_frd(omega_flu_rad_s))


def _yawspeed(q_enu_flu: Quat, omega_flu_rad_s: Vec3) -> float:
    """Rate about NED z (down) of a body turning at omega_flu_rad_s."""
    return -q_rotate(q_enu_flu, omega_flu_rad_s)[2]


_NAN = math.nan


def trajectory_setpoint_record(t_us: int, p_enu_m: Vec3, v_enu_m_s: Vec3, a_enu_m_s2: Vec3,
                               q_enu_flu: Quat, omega_flu_rad_s: Vec3
                               ) -> tuple[float | int, ...]:
    """trajectory_setpoint: NED position, velocity, acceleration (jerk NaN: not set), yaw and
    yaw rate of the reference."""
    return (t_us, *enu_to_ned(p_enu_m), *enu_to_ned(v_enu_m_s), *enu_to_ned(a_enu_m_s2),
            _NAN, _NAN, _NAN, zyx_yaw(q_enu_flu_to_ned_frd(q_enu_flu)),
            _yawspeed(q_enu_flu, omega_flu_rad_s))


def local_position_setpoint_record(t_us: int, p_enu_m: Vec3, v_enu_m_s: Vec3,
                                   a_enu_m_s2: Vec3, q_enu_flu: Quat, omega_flu_rad_s: Vec3
                                   ) -> tuple[float | int, ...]:
    """vehicle_local_position_setpoint: the same reference, PX4's older layout."""
    return (t_us, *enu_to_ned(p_enu_m), *enu_to_ned(v_enu_m_s), *enu_to_ned(a_enu_m_s2),
            zyx_yaw(q_enu_flu_to_ned_frd(q_enu_flu)), _yawspeed(q_enu_flu, omega_flu_rad_s))


def attitude_setpoint_record(t_us: int, q_enu_flu: Quat, omega_flu_rad_s: Vec3
                             ) -> tuple[float | int | bool, ...]:
    """vehicle_attitude_setpoint: the desired attitude FRD->NED and its yaw rate."""
    return (t_us, _yawspeed(q_enu_flu, omega_flu_rad_s), *q_enu_flu_to_ned_frd(q_enu_flu),
            False)


def rates_setpoint_record(t_us: int, omega_flu_rad_s: Vec3) -> tuple[float | int | bool, ...]:
    """vehicle_rates_setpoint: the desired body rate in FRD."""
    return (t_us, *flu_to_frd(omega_flu_rad_s), False)


def actuator_motors_record(t_us: int, stamp_us: int, speed_rad_s: tuple[float, ...],
                           speed_max_rad_s: float, armed: bool) -> tuple[float | int, ...]:
    """actuator_motors: speed / limit in [0, 1] per rotor; NaN (stopped, PX4's disarmed
    value) when disarmed and for the unused outputs."""
    n = len(speed_rad_s)
    motors = [s / speed_max_rad_s if armed else _NAN for s in speed_rad_s]
    return (t_us, stamp_us, 0, *motors, *[_NAN] * (12 - n))


def actuator_servos_record(t_us: int, stamp_us: int, tilt_rad: tuple[float, ...]
                           ) -> tuple[float | int, ...]:
    """actuator_servos: each tilt wrapped to [-pi, pi) and divided by pi, in [-1, 1); NaN for
    the unused outputs. The unwrapped angle is in dq_onboard."""
    servos = [((a + math.pi) % (2.0 * math.pi) - math.pi) / math.pi for a in tilt_rad]
    return (t_us, stamp_us, *servos, *[_NAN] * (8 - len(tilt_rad)))


def control_allocator_status_record(t_us: int, speed_rad_s: tuple[float, ...],
                                    speed_max_rad_s: float, armed: bool, saturated: bool
                                    ) -> tuple[float | int | bool, ...]:
    """control_allocator_status: whether the wrench was achieved, and which rotors sit at
    their upper (full speed) or lower (stopped while armed) limit."""
    flags = [ACTUATOR_SATURATION_UPPER if s >= speed_max_rad_s else
             ACTUATOR_SATURATION_LOWER if s <= 0.0 and armed else 0 for s in speed_rad_s]
    achieved = not saturated
    return (t_us, achieved, achieved, *flags, *[0] * (16 - len(speed_rad_s)), 0)


# ---------------------------------------------------------------------------------------------
# The estimator (EKF_EN = 1): its inputs and its state, as PX4 logs EKF2's
# ---------------------------------------------------------------------------------------------
# These layouts are kept in one tuple (ESTIMATOR_TOPICS, by name in ESTIMATOR_TOPIC), apart
# from the module's single-topic constants above, which every log declares and fills.

ESTIMATOR_TOPICS: tuple[Topic, ...] = (
    # sensor_combined.msg: each IMU sample the estimator received, FRD, as on the wire
    Topic("sensor_combined", (
        _T, ("float", "gyro_rad", 3), ("uint32_t", "gyro_integral_dt"),
        ("int32_t", "accelerometer_timestamp_relative"), ("float", "accelerometer_m_s2", 3),
        ("uint32_t", "accelerometer_integral_dt"))),
    # vehicle_odometry.msg (TOPICS ... vehicle_visual_odometry): each external pose received
    Topic("vehicle_visual_odometry", (
        _T, _TS, ("uint8_t", "pose_frame"), ("float", "position", 3), ("float", "q", 4),
        ("uint8_t", "velocity_frame"), ("float", "velocity", 3),
        ("float", "position_variance", 3), ("float", "orientation_variance", 3),
        ("int8_t", "quality"))),
    # estimator_states.msg
    Topic("estimator_states", (
        _T, _TS, ("float", "states", 24), ("uint8_t", "n_states"),
        ("float", "covariances", 24))),
    # estimator_innovations.msg (TOPICS estimator_innovations estimator_innovation_variances
    # estimator_innovation_test_ratios): the external-vision position and the heading
    Topic("estimator_innovations", (
        _T, _TS, ("float", "ev_hpos", 2), ("float", "ev_vpos"), ("float", "heading"))),
    Topic("estimator_innovation_test_ratios", (
        _T, _TS, ("float", "ev_hpos", 2), ("float", "ev_vpos"), ("float", "heading"))),
    # estimator_status.msg
    Topic("estimator_status", (
        _T, _TS, ("uint16_t", "gps_check_fail_flags"), ("uint64_t", "control_mode_flags"),
        ("uint32_t", "filter_fault_flags"), ("float", "pos_horiz_accuracy"),
        ("float", "pos_vert_accuracy"), ("float", "mag_test_ratio"),
        ("float", "pos_test_ratio"), ("float", "hgt_test_ratio"),
        ("uint16_t", "solution_status_flags"))),
)
ESTIMATOR_TOPIC = {t.name: t for t in ESTIMATOR_TOPICS}

POSE_FRAME_NED = 1  # vehicle_odometry.pose_frame
VELOCITY_FRAME_UNKNOWN = 0  # vehicle_odometry.velocity_frame: no velocity measured
ODOMETRY_QUALITY_UNKNOWN = 0  # vehicle_odometry.quality (MAVLink ODOMETRY's: 0 unknown)
N_STATES = 16  # estimator_states.n_states: q, v, p, gyro bias, accel bias (no mag, no wind)
# estimator_status.control_mode_flags bits (estimator_status_flags.msg's cs_* order)
CS_TILT_ALIGN = 0
CS_YAW_ALIGN = 1
CS_IN_AIR = 7
CS_EV_POS = 12
CS_EV_YAW = 13
CS_EV_HGT = 14
CS_INERTIAL_DEAD_RECKONING = 29
# estimator_status.filter_fault_flags bits: numerical errors in the position fusion
FS_BAD_POS_N = 12
FS_BAD_POS_E = 13
FS_BAD_POS_D = 14
# estimator_status.solution_status_flags bits (EKF's ekf_solution_status)
SOL_ATTITUDE = 0
SOL_VELOCITY_HORIZ = 1
SOL_VELOCITY_VERT = 2
SOL_POS_HORIZ_REL = 3
SOL_POS_VERT_ABS = 5
SOL_PRED_POS_HORIZ_REL = 8


def _bits(q: Quat) -> bytes:
    return struct.pack("<4d", *q)


def _f32_neighbours(x: float) -> list[float]:
    """x (a float32 value), the float32 values two steps either side of it, and 0."""
    out = [x]
    for step in (1, -1):
        v = x
        for _ in range(2):
            v = float(np.nextafter(np.float32(v), np.float32(step * math.inf)))
            out.append(v)
    out.append(0.0)
    return out


def wire_q_ned_frd(q_enu_flu: Quat) -> Quat:
    """A float32 q_ned_frd that `q_ned_frd_to_enu_flu` takes to exactly q_enu_flu (when
    q_enu_flu came from a float32 quaternion on the wire): the attitude a replay converts
    back to the very value the FCU received.

    The conversion rounds (it multiplies by sqrt(1/2)), so the float32 rounding of the
    inverse is checked; when it misses, each pair of components that the conversion mixes,
    (w, z) and (x, y), is searched over the float32 values next to it and 0. A component
    below about 1e-9 of its pair's other one can still miss (the conversion lost most of
    it): then the rounding of the inverse, which agrees to float64 rounding."""
    q = f32_quat(q_enu_flu_to_ned_frd(q_enu_flu))
    back = q_ned_frd_to_enu_flu(q)
    if back == q_enu_flu and 0.0 not in back:  # equal and no zero whose sign could differ
        return q
    target = _bits(q_enu_flu)
    if _bits(back) == target:
        return q
    best = list(q)
    for i, j in ((0, 3), (1, 2)):  # (w, z) makes components 0 and 3 of the result, (x, y) 1, 2
        want = (struct.pack("<d", q_enu_flu[i]), struct.pack("<d", q_enu_flu[j]))
        for a in _f32_neighbours(q[i]):
            done = False
            for b in _f32_neighbours(q[j]):
                t = list(best)
                t[i], t[j] = a, b
                r = q_ned_frd_to_enu_flu((t[0], t[1], t[2], t[3]))
                if (struct.pack("<d", r[i]), struct.pack("<d", r[j])) == want:
                    best, done = t, True
                    break
            if done:
                break
    found: Quat = (best[0], best[1], best[2], best[3])
    return found if _bits(q_ned_frd_to_enu_flu(found)) == target else q


def sensor_combined_record(t_us: int, omega_flu_rad_s: Vec3, f_flu_m_s2: Vec3, dt_us: int
                           ) -> tuple[float | int, ...]:
    """sensor_combined: one IMU sample in FRD (the HIL_SENSOR's float32 values: FLU<->FRD
    only flips signs), integrated over dt_us (the time since the previous sample)."""
    return (t_us, *flu_to_frd(omega_flu_rad_s), dt_us, 0, *flu_to_frd(f_flu_m_s2), dt_us)


def visual_odometry_record(t_us: int, capture_us: int, p_enu_m: Vec3, q_enu_flu: Quat,
                           pos_var_m2: float, att_var_rad2: float) -> tuple[float | int, ...]:
    """vehicle_visual_odometry: an external pose in NED (position, FRD->NED attitude from
    `wire_q_ned_frd`), no velocity (NaN), the per-axis variances (NaN: none given)."""
    return (t_us, capture_us, POSE_FRAME_NED, *enu_to_ned(p_enu_m), *wire_q_ned_frd(q_enu_flu),
            VELOCITY_FRAME_UNKNOWN, _NAN, _NAN, _NAN, pos_var_m2, pos_var_m2, pos_var_m2,
            att_var_rad2, att_var_rad2, att_var_rad2, ODOMETRY_QUALITY_UNKNOWN)


def estimator_states_record(t_us: int, stamp_us: int, p_enu_m: Vec3, v_enu_m_s: Vec3,
                            q_enu_flu: Quat, gyro_bias_flu: Vec3, accel_bias_flu: Vec3,
                            variances: Sequence[float]) -> tuple[float | int, ...]:
    """estimator_states in EKF2's order: states = q (FRD->NED), velocity NED, position NED,
    gyro bias (rad/s, FRD), accelerometer bias (m/s^2, FRD), then 0 for the states this
    filter does not have (magnetic field, wind); covariances = the error-state diagonal in
    the same order (attitude error, velocity, position, gyro bias, accel bias), 0 after.
    `variances` is the diagonal in the estimator's order (p, v, theta, b_g, b_a; ENU/FLU)."""
    d = variances
    cov = (d[6], d[7], d[8], d[4], d[3], d[5], d[1], d[0], d[2], *d[9:15])
    states = (*q_enu_flu_to_ned_frd(q_enu_flu), *enu_to_ned(v_enu_m_s), *enu_to_ned(p_enu_m),
              *flu_to_frd(gyro_bias_flu), *flu_to_frd(accel_bias_flu))
    return (t_us, stamp_us, *states, *[0.0] * (24 - len(states)), N_STATES,
            *cov, *[0.0] * (24 - len(cov)))


def estimator_innovations_record(t_us: int, stamp_us: int, pos_innov_enu_m: Vec3,
                                 att_innov_flu_rad: Vec3, q_enu_flu: Quat
                                 ) -> tuple[float | int, ...]:
    """estimator_innovations of the last pose, as EKF2 signs them (prediction minus
    measurement): ev_hpos, ev_vpos in NED; heading = the attitude innovation's component
    about NED down. The estimator's innovations are measurement minus prediction, the
    attitude one a rotation vector in the body frame."""
    n, e, d = enu_to_ned(pos_innov_enu_m)
    up = q_rotate(q_enu_flu, att_innov_flu_rad)[2]  # measured - predicted, about ENU up
    return (t_us, stamp_us, -n, -e, -d, up)  # about down: -up; prediction - measurement: up


def estimator_test_ratios_record(t_us: int, stamp_us: int, pos_ratio: float, att_ratio: float
                                 ) -> tuple[float | int, ...]:
    """estimator_innovation_test_ratios: innov^2 / (gate^2 S) of the last pose; the
    estimator gates the position as one (the largest axis' ratio) and the attitude as one."""
    return (t_us, stamp_us, pos_ratio, pos_ratio, pos_ratio, att_ratio)


def estimator_status_record(t_us: int, stamp_us: int, *, aligned: bool, healthy: bool,
                            in_air: bool, dead_reckoning: bool, pos_sd_enu_m: Vec3,
                            pos_ratio: float, att_ratio: float) -> tuple[float | int, ...]:
    """estimator_status: control_mode_flags (tilt and yaw aligned, in air, fusing the external
    position, yaw and height, or dead-reckoning), filter_fault_flags (a failed estimate as
    position numerical errors), horizontal and vertical position accuracy (sd, m), the pose's
    test ratios (heading in mag_test_ratio, as EKF2 reports it), solution_status_flags."""
    mode = 0
    if aligned:
        mode |= 1 << CS_TILT_ALIGN | 1 << CS_YAW_ALIGN
        mode |= (1 << CS_INERTIAL_DEAD_RECKONING if dead_reckoning else
                 1 << CS_EV_POS | 1 << CS_EV_YAW | 1 << CS_EV_HGT)
    if in_air:
        mode |= 1 << CS_IN_AIR
    faults = 0
    solution = 0
    if aligned and not healthy:
        faults = 1 << FS_BAD_POS_N | 1 << FS_BAD_POS_E | 1 << FS_BAD_POS_D
    elif aligned:
        for bit in (SOL_ATTITUDE, SOL_VELOCITY_HORIZ, SOL_VELOCITY_VERT, SOL_POS_HORIZ_REL,
                    SOL_POS_VERT_ABS, SOL_PRED_POS_HORIZ_REL):
            solution |= 1 << bit
    sx, sy, sz = pos_sd_enu_m
    return (t_us, stamp_us, 0, mode, faults, math.sqrt(sx * sx + sy * sy), sz,
            att_ratio, pos_ratio, pos_ratio, solution)
