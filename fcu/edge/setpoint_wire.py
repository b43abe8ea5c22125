"""The FCU's MAVLink edge for set-points: SET_POSITION_TARGET_LOCAL_NED and
SET_ATTITUDE_TARGET decoded into the commander's typed targets (`fcu.modes.offboard_stream`), in
the code's frames (ENU world, FLU body) and SI units, and MANUAL_CONTROL into stick
deflections (`fcu.modes.manual.Sticks`).

The wire gives positions, velocities and accelerations in MAV_FRAME_LOCAL_NED (the only
frame taken), a yaw in NED (the heading of a level attitude), an attitude NED -> FRD and body
rates in FRD. A `type_mask` bit set ignores a field: any of the three bits of a vector ignores
the whole vector (POSITION_TARGET_TYPEMASK), ATTITUDE_IGNORE the attitude and any
BODY_*_RATE_IGNORE the rates (ATTITUDE_TARGET_TYPEMASK). What the wire cannot mean (another
frame, a quaternion far from unit length) raises `SetpointRefused` with the STATUSTEXT to
send; the commander checks the rest against its limits.

MANUAL_CONTROL as QGroundControl's virtual joystick sends it to PX4: x = forward (pitch
stick), y = right (roll stick), r = yaw clockwise, each -1000..1000, and z = throttle
0..1000 with 500 at the centre (PX4's convention for position and altitude modes: the centre
holds the altitude); INT16_MAX marks an axis that is not given (taken as centred).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from common.frames import frd_to_flu, ned_to_enu, q_ned_frd_to_enu_flu
from common.wire.mav_enums import ATTITUDE_TARGET_TYPEMASK as ATT
from common.wire.mav_enums import MAV_FRAME
from common.wire.mav_enums import POSITION_TARGET_TYPEMASK as POS
from fcu.control.dualquat import Quat, Vec3
from fcu.mission.segments import level_attitude
from fcu.modes.manual import Sticks
from fcu.modes.offboard_stream import AttitudeTarget, PositionTarget

POSITION_IGNORE = POS.POSITION_TARGET_TYPEMASK_X_IGNORE | \
    POS.POSITION_TARGET_TYPEMASK_Y_IGNORE | POS.POSITION_TARGET_TYPEMASK_Z_IGNORE
VELOCITY_IGNORE = POS.POSITION_TARGET_TYPEMASK_VX_IGNORE | \
    POS.POSITION_TARGET_TYPEMASK_VY_IGNORE | POS.POSITION_TARGET_TYPEMASK_VZ_IGNORE
ACCELERATION_IGNORE = POS.POSITION_TARGET_TYPEMASK_AX_IGNORE | \
    POS.POSITION_TARGET_TYPEMASK_AY_IGNORE | POS.POSITION_TARGET_TYPEMASK_AZ_IGNORE
RATES_IGNORE = ATT.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE | \
    ATT.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE | \
    ATT.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
UNIT_NORM_MIN = 0.5  # a quaternion shorter than this (or not finite) is no attitude
STICK_MAX = 1000  # MANUAL_CONTROL x, y, r: -1000..1000
THROTTLE_CENTRE = 500  # MANUAL_CONTROL z: 0..1000, 500 holds the altitude (PX4)
INVALID_AXIS = 32767  # INT16_MAX: the axis is not given


class SetpointRefused(ValueError):
    """A set-point message the wire format cannot mean; str() is the STATUSTEXT."""


def position_target(frame: int, type_mask: int, p_ned_m: Vec3, v_ned_m_s: Vec3,
                    a_ned_m_s2: Vec3, yaw_ned_rad: float,
                    yaw_rate_ned_rad_s: float = 0.0) -> PositionTarget:
    """SET_POSITION_TARGET_LOCAL_NED's fields as a `PositionTarget` (ENU); a yaw that is not
    finite is no heading. Refused rather than flown otherwise: forces (FORCE_SET: afx..afz
    are newtons, not accelerations) and a finite yaw rate other than 0 (not flown here: the
    heading follows `yaw`, or is held)."""
    if frame != MAV_FRAME.MAV_FRAME_LOCAL_NED:
        raise SetpointRefused("position target frame must be LOCAL_NED")
    if type_mask & POS.POSITION_TARGET_TYPEMASK_FORCE_SET and \
            (type_mask & ACCELERATION_IGNORE) != ACCELERATION_IGNORE:
        raise SetpointRefused("position target: force set-points (FORCE_SET) not taken")
    if not type_mask & POS.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE and \
            math.isfinite(yaw_rate_ned_rad_s) and yaw_rate_ned_rad_s != 0.0:
        raise SetpointRefused("position target: yaw rate not taken (give yaw)")
    yaw_given = not type_mask & POS.POSITION_TARGET_TYPEMASK_YAW_IGNORE and \
        math.isfinite(yaw_ned_rad)
    return PositionTarget(
        None if type_mask & POSITION_IGNORE else ned_to_enu(p_ned_m),
        None if type_mask & VELOCITY_IGNORE else ned_to_enu(v_ned_m_s),
        None if type_mask & ACCELERATION_IGNORE else ned_to_enu(a_ned_m_s2),
        level_attitude(math.degrees(yaw_ned_rad)) if yaw_given else None)


def attitude_target(type_mask: int, q_ned_frd: Sequence[float],
                    rates_frd_rad_s: Vec3) -> AttitudeTarget:
    """SET_ATTITUDE_TARGET's attitude (w, x, y, z as the wire carries it; normalised,
    NED -> FRD) and body rates (FRD) as an `AttitudeTarget` (ENU -> FLU, FLU); the thrust
    is not used."""
    q: Quat | None = None
    if not type_mask & ATT.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE:
        n = math.sqrt(sum(c * c for c in q_ned_frd))
        if not math.isfinite(n) or n < UNIT_NORM_MIN:
            raise SetpointRefused("attitude target not a unit quaternion")
        w, x, y, z = (c / n for c in q_ned_frd)
        q = q_ned_frd_to_enu_flu((w, x, y, z))
    rates = None if type_mask & RATES_IGNORE else frd_to_flu(rates_frd_rad_s)
    return AttitudeTarget(q, rates)


def sticks_from_manual_control(x: int, y: int, z: int, r: int) -> Sticks:
    """MANUAL_CONTROL's x, y, z, r as deflections (module docstring); values beyond the
    ranges are clamped, INT16_MAX is a centred axis."""
    def axis(v: int) -> float:
        if v == INVALID_AXIS:
            return 0.0
        return max(-1.0, min(1.0, v / STICK_MAX))

    up = 0.0 if z == INVALID_AXIS else \
        max(-1.0, min(1.0, (z - THROTTLE_CENTRE) / (STICK_MAX - THROTTLE_CENTRE)))
    return Sticks(axis(x), axis(y), up, axis(r))
