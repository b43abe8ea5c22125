"""Health and readiness from what an autopilot says: SYS_STATUS sensor bits, ArduPilot's
EKF_STATUS_REPORT, and the STATUSTEXTs in which autopilots say why they will not arm.

Health counts the sensors the autopilot has ENABLED (a present but disabled one, such as an
ArduCopter's position controllers on the ground, is not a fault). Readiness is its own
thing: the PREARM_CHECK bit (ArduPilot and PX4 set it healthy when arming would pass), the
estimator's state (ArduPilot's EKF flags), and the reasons heard ("PreArm: ...",
"Arm: ...", PX4's "Preflight Fail: ...", "Arming denied: ...").
"""

from __future__ import annotations

from typing import Any

from common.wire.mavlink import MAV

M = MAV
PREARM = M.MAV_SYS_STATUS_PREARM_CHECK
_SENSORS = {bit: e.name.replace("MAV_SYS_STATUS_SENSOR_", "").replace("MAV_SYS_STATUS_", "")
            for bit, e in M.enums["MAV_SYS_STATUS_SENSOR"].items()
            if bit and bit & (bit - 1) == 0 and not e.name.endswith("ENUM_END")}

# ArduPilot's EKF_STATUS_REPORT.flags (ardupilotmega EKF_STATUS_FLAGS)
EKF_ATTITUDE, EKF_VELOCITY_HORIZ, EKF_VELOCITY_VERT = 1, 2, 4
EKF_POS_HORIZ_REL, EKF_POS_HORIZ_ABS, EKF_POS_VERT_ABS = 8, 16, 32
EKF_CONST_POS_MODE, EKF_UNINITIALIZED, EKF_GPS_GLITCHING = 128, 1024, 32768
EKF_NEEDED = {EKF_ATTITUDE: "attitude", EKF_VELOCITY_HORIZ: "horizontal velocity",
              EKF_VELOCITY_VERT: "vertical velocity", EKF_POS_HORIZ_ABS: "horizontal position",
              EKF_POS_VERT_ABS: "vertical position"}
EKF_BAD = {EKF_CONST_POS_MODE: "constant position mode", EKF_UNINITIALIZED: "uninitialised",
           EKF_GPS_GLITCHING: "GPS glitching"}
REASON_PREFIXES = ("PreArm:", "Arm:", "Preflight Fail", "Arming denied")


def sensor_names(bits: int) -> list[str]:
    """The MAV_SYS_STATUS_SENSOR names of the bits set, without the prefix."""
    return [name for bit, name in _SENSORS.items() if bits & bit]


def health(sys_status: Any) -> str:
    """"ok" when every enabled sensor is healthy, else "unhealthy sensors: A, B". The
    PREARM_CHECK bit is readiness, not health (`readiness`)."""
    enabled = sys_status.onboard_control_sensors_enabled & \
        sys_status.onboard_control_sensors_present
    bad = enabled & ~sys_status.onboard_control_sensors_health & ~PREARM
    return "ok" if not bad else "unhealthy sensors: " + ", ".join(sensor_names(bad))


def ekf_state(flags: int) -> str:
    """ArduPilot's estimator: "ok", or what it lacks and what is wrong with it."""
    lacking = [name for bit, name in EKF_NEEDED.items() if not flags & bit]
    wrong = [name for bit, name in EKF_BAD.items() if flags & bit]
    if not lacking and not wrong:
        return "ok"
    return "; ".join(([f"no {', '.join(lacking)}"] if lacking else []) + wrong)


def readiness(sys_status: Any, ekf_status: Any, texts: list[str], *,
              prearm_in_health: bool = False) -> dict[str, Any]:
    """{"ready_to_arm": bool or None (unknown), "ekf": ArduPilot's estimator state (where
    reported), "reasons": the autopilot's latest why-not texts}. The PREARM_CHECK bit is
    read where the autopilot says it has one (`present`); PX4 sets it in `health` only
    (its SYS_STATUS stream), so with `prearm_in_health` the health bit alone decides."""
    out: dict[str, Any] = {"ready_to_arm": None}
    if sys_status is not None and (prearm_in_health or
                                   sys_status.onboard_control_sensors_present & PREARM):
        out["ready_to_arm"] = bool(sys_status.onboard_control_sensors_health & PREARM)
    if ekf_status is not None:
        out["ekf"] = ekf_state(ekf_status.flags)
    reasons = [t for t in texts if t.startswith(REASON_PREFIXES)]
    if reasons and out["ready_to_arm"] is not True:
        out["reasons"] = list(dict.fromkeys(reasons))
    return out


def format_readiness(value: dict[str, Any]) -> str:
    """`readiness` for people: "ready to arm, EKF ok" or "not ready: <reasons>"."""
    ready = value.get("ready_to_arm")
    parts = ["ready to arm" if ready else "not ready to arm" if ready is False
             else "unknown"]
    if "ekf" in value:
        parts.append(f"EKF {value['ekf']}")
    parts += value.get("reasons", [])
    return ", ".join(parts)
