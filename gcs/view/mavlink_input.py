"""The live view's input: a sample updated from the vehicle's standard MAVLink telemetry
(NED/FRD on the wire, ENU/FLU in the sample, converted by `common.frames` only)."""

from __future__ import annotations

from typing import Any

from common.frames import ned_to_enu, q_ned_frd_to_enu_flu
from common.mavlink import MAV
from common.quaternion import Q_IDENTITY
from gcs.vehicle_link.status import mode_name
from gcs.view.sample import Pose, Sample


def apply_message(sample: Sample, msg: Any) -> bool:
    """Update a sample from one MAVLink message (pymavlink object); True if it changed.

    ACTUATOR_OUTPUT_STATUS counts only with its first 12 outputs active (this project's
    packing: six speeds, six tilts); other autopilots' outputs are left out."""
    kind = msg.get_type()
    if kind == "LOCAL_POSITION_NED":
        q = sample.pose.q_enu_flu if sample.pose is not None else Q_IDENTITY
        sample.pose = Pose(ned_to_enu((msg.x, msg.y, msg.z)), q)
        sample.pose_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "ATTITUDE_QUATERNION":
        p = sample.pose.p_enu_m if sample.pose is not None else (0.0, 0.0, 0.0)
        sample.pose = Pose(p, q_ned_frd_to_enu_flu((msg.q1, msg.q2, msg.q3, msg.q4)))
        if sample.pose_time_us is None:
            sample.pose_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "POSITION_TARGET_LOCAL_NED":
        if msg.type_mask & 0b111:  # position ignored: a velocity or acceleration target
            return False
        q = sample.desired.q_enu_flu if sample.desired is not None else Q_IDENTITY
        sample.desired = Pose(ned_to_enu((msg.x, msg.y, msg.z)), q)
        sample.desired_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "ATTITUDE_TARGET":
        if msg.type_mask & 0b1000_0000:  # attitude ignored
            return False
        p = sample.desired.p_enu_m if sample.desired is not None else (0.0, 0.0, 0.0)
        q1, q2, q3, q4 = (float(v) for v in msg.q)
        sample.desired = Pose(p, q_ned_frd_to_enu_flu((q1, q2, q3, q4)))
        if sample.desired_time_us is None:
            sample.desired_time_us = int(msg.time_boot_ms) * 1000
    elif kind == "ACTUATOR_OUTPUT_STATUS":
        if msg.active & 0xFFF != 0xFFF:
            return False
        values = [float(v) for v in msg.actuator[:12]]
        sample.rotor_speeds_rad_s = tuple(values[:6])
        sample.tilts_rad = tuple(values[6:12])
        sample.actuator_time_us = int(msg.time_usec)
    elif kind == "HEARTBEAT":
        sample.mode = mode_name(msg.custom_mode, msg.autopilot, msg.type)
        sample.armed = bool(msg.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED)
    else:
        return False
    return True

