"""PX4's uORB message layouts for the ULog logs: names, fields, types and frames as PX4
defines them (msg/*.msg, v1.15), so Flight Review, PlotJuggler and pyulog scripts written
for PX4 logs read ours.

Only the fields this vehicle has a value for are declared (a ULog format names its fields,
so a reader looks them up by name). PX4 conventions: float32, local frame NED, body frame
FRD, quaternions Hamilton [w, x, y, z] rotating FRD into NED, timestamps in microseconds.
What PX4 has no topic for, and the float64 values the metrics need, are in the project's
own topics (`dq_truth` in sitl.truth_log, `dq_onboard` in fcu.onboard_log).
"""

from __future__ import annotations

import math

from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.quaternion import Quat, Vec3, q_rotate
from common.ulog import Topic

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

def yaw_ned(q_ned_frd: Quat) -> float:
    """Heading of an FRD->NED attitude (Z-Y-X yaw), rad."""
    w, x, y, z = q_ned_frd
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def local_position_record(t_us: int, stamp_us: int, p_enu_m: Vec3, v_enu_m_s: Vec3,
                          q_enu_flu: Quat, valid: bool,
                          ref: tuple[int, float, float, float] | None
                          ) -> tuple[float | int | bool, ...]:
    """vehicle_local_position[_groundtruth]: NED position, velocity and heading; `ref` is
    (ref_timestamp, ref_lat, ref_lon, ref_alt) of the local frame's origin, None when the
    origin has no global position (xy_global and z_global false)."""
    origin = ref is not None
    return (t_us, stamp_us, valid, valid, valid, valid, *enu_to_ned(p_enu_m),
            *enu_to_ned(v_enu_m_s), yaw_ned(q_enu_flu_to_ned_frd(q_enu_flu)), origin, origin,
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
            _NAN, _NAN, _NAN, yaw_ned(q_enu_flu_to_ned_frd(q_enu_flu)),
            _yawspeed(q_enu_flu, omega_flu_rad_s))


def local_position_setpoint_record(t_us: int, p_enu_m: Vec3, v_enu_m_s: Vec3,
                                   a_enu_m_s2: Vec3, q_enu_flu: Quat, omega_flu_rad_s: Vec3
                                   ) -> tuple[float | int, ...]:
    """vehicle_local_position_setpoint: the same reference, PX4's older layout."""
    return (t_us, *enu_to_ned(p_enu_m), *enu_to_ned(v_enu_m_s), *enu_to_ned(a_enu_m_s2),
            yaw_ned(q_enu_flu_to_ned_frd(q_enu_flu)), _yawspeed(q_enu_flu, omega_flu_rad_s))


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
