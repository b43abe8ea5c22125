"""The live view's input: a sample updated from the vehicle's standard MAVLink telemetry
(NED/FRD on the wire, ENU/FLU in the sample, converted by `common.frames` only)."""

from __future__ import annotations

from typing import Any

from common.frames import ned_to_enu, q_ned_frd_to_enu_flu
from common.quaternion import Q_IDENTITY
from common.wire.mav_enums import ATTITUDE_TARGET_TYPEMASK as ATT
from common.wire.mav_enums import MAV_MODE_FLAG
from common.wire.mav_enums import POSITION_TARGET_TYPEMASK as POS
from common.wire.mavlink_types import as_message
from common.wire.mavlink_types.state import (
    ActuatorOutputStatus,
    AttitudeQuaternion,
    AttitudeTarget,
    Heartbeat,
    LocalPositionNed,
    PositionTargetLocalNed,
)
from gcs.vehicle_link.status import mode_name
from gcs.view.sample import Pose, Sample

POSITION_IGNORE = POS.POSITION_TARGET_TYPEMASK_X_IGNORE | \
    POS.POSITION_TARGET_TYPEMASK_Y_IGNORE | POS.POSITION_TARGET_TYPEMASK_Z_IGNORE


def apply_message(sample: Sample, msg: Any) -> bool:
    """Update a sample from one MAVLink message (pymavlink object); True if it changed.

    ACTUATOR_OUTPUT_STATUS counts only with its first 12 outputs active (this project's
    packing: six speeds, six tilts); other autopilots' outputs are left out."""
    kind = msg.get_type()
    if kind == "LOCAL_POSITION_NED":
        pos = as_message(msg, LocalPositionNed)
        q = sample.pose.q_enu_flu if sample.pose is not None else Q_IDENTITY
        sample.pose = Pose(ned_to_enu((pos.x, pos.y, pos.z)), q)
        sample.pose_time_us = int(pos.time_boot_ms) * 1000
    elif kind == "ATTITUDE_QUATERNION":
        att = as_message(msg, AttitudeQuaternion)
        p = sample.pose.p_enu_m if sample.pose is not None else (0.0, 0.0, 0.0)
        sample.pose = Pose(p, q_ned_frd_to_enu_flu((att.q1, att.q2, att.q3, att.q4)))
        if sample.pose_time_us is None:
            sample.pose_time_us = int(att.time_boot_ms) * 1000
    elif kind == "POSITION_TARGET_LOCAL_NED":
        pos_target = as_message(msg, PositionTargetLocalNed)
        if pos_target.type_mask & POSITION_IGNORE:  # a velocity or acceleration target
            return False
        q = sample.desired.q_enu_flu if sample.desired is not None else Q_IDENTITY
        sample.desired = Pose(ned_to_enu((pos_target.x, pos_target.y, pos_target.z)), q)
        sample.desired_time_us = int(pos_target.time_boot_ms) * 1000
    elif kind == "ATTITUDE_TARGET":
        att_target = as_message(msg, AttitudeTarget)
        if att_target.type_mask & ATT.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE:
            return False
        p = sample.desired.p_enu_m if sample.desired is not None else (0.0, 0.0, 0.0)
        q1, q2, q3, q4 = (float(v) for v in att_target.q)
        sample.desired = Pose(p, q_ned_frd_to_enu_flu((q1, q2, q3, q4)))
        if sample.desired_time_us is None:
            sample.desired_time_us = int(att_target.time_boot_ms) * 1000
    elif kind == "ACTUATOR_OUTPUT_STATUS":
        out = as_message(msg, ActuatorOutputStatus)
        if out.active & 0xFFF != 0xFFF:
            return False
        values = [float(v) for v in out.actuator[:12]]
        sample.rotor_speeds_rad_s = tuple(values[:6])
        sample.tilts_rad = tuple(values[6:12])
        sample.actuator_time_us = int(out.time_usec)
    elif kind == "HEARTBEAT":
        hb = as_message(msg, Heartbeat)
        sample.mode = mode_name(hb.custom_mode, hb.autopilot, hb.type)
        sample.armed = bool(hb.base_mode & MAV_MODE_FLAG.MAV_MODE_FLAG_SAFETY_ARMED)
    else:
        return False
    return True
