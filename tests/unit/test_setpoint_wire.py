"""The FCU's MAVLink edge for set-points (fcu/edge/setpoint_wire.py): type_mask bits, MAV_FRAME
and NED/FRD decoded into the commander's ENU/FLU targets; what the wire cannot mean is
refused with the STATUSTEXT the commander used to send."""

from __future__ import annotations

import math

import pytest

from common.frames import q_enu_flu_to_ned_frd
from common.quaternion import q_angle, q_conj, q_exp, q_mul
from common.wire.mavlink import MAV as M
from fcu.edge.setpoint_wire import SetpointRefused, attitude_target, position_target

Z3 = (0.0, 0.0, 0.0)


def test_position_velocity_acceleration_and_yaw_in_enu():
    t = position_target(M.MAV_FRAME_LOCAL_NED, 0, (1.0, 2.0, -3.0), (4.0, 5.0, -6.0),
                        (7.0, 8.0, -9.0), math.radians(90.0))
    assert t.p_enu_m == (2.0, 1.0, 3.0) and t.v_enu_m_s == (5.0, 4.0, 6.0)
    assert t.a_enu_m_s2 == (8.0, 7.0, 9.0)
    assert t.has_heading and q_angle(t.q_level_enu_flu) < 1e-12  # NED yaw 90 deg: east


@pytest.mark.parametrize("bit, part", [(M.POSITION_TARGET_TYPEMASK_X_IGNORE, "p_enu_m"),
                                       (M.POSITION_TARGET_TYPEMASK_VZ_IGNORE, "v_enu_m_s"),
                                       (M.POSITION_TARGET_TYPEMASK_AY_IGNORE, "a_enu_m_s2"),
                                       (M.POSITION_TARGET_TYPEMASK_YAW_IGNORE,
                                        "q_level_enu_flu")])
def test_any_ignore_bit_of_a_part_drops_the_part(bit, part):
    t = position_target(M.MAV_FRAME_LOCAL_NED, bit, (1.0, 2.0, 3.0), Z3, Z3, 0.0)
    assert getattr(t, part) is None
    assert all(getattr(t, other) is not None for other in t._fields if other != part)


def test_a_yaw_not_finite_is_no_heading_and_other_frames_are_refused():
    assert not position_target(M.MAV_FRAME_LOCAL_NED, 0, Z3, Z3, Z3, math.nan).has_heading
    with pytest.raises(SetpointRefused, match="frame must be LOCAL_NED"):
        position_target(M.MAV_FRAME_BODY_NED, 0, Z3, Z3, Z3, 0.0)


def test_forces_and_a_yaw_rate_are_refused_not_flown_as_something_else():
    """FORCE_SET makes afx..afz newtons: refused, not flown as accelerations (PX4 drops
    force set-points too); ignored accelerations with the bit set pass. A yaw rate given (bit
    clear, finite, not 0) is refused with the reason, where it was dropped and the heading
    held; 0, not finite, or ignored pass."""
    force = M.POSITION_TARGET_TYPEMASK_FORCE_SET | M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
    with pytest.raises(SetpointRefused, match="FORCE_SET"):
        position_target(M.MAV_FRAME_LOCAL_NED, force, Z3, Z3, (2.0, 0.0, 0.0), 0.0)
    no_accel = force | M.POSITION_TARGET_TYPEMASK_AX_IGNORE | \
        M.POSITION_TARGET_TYPEMASK_AY_IGNORE | M.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    assert position_target(M.MAV_FRAME_LOCAL_NED, no_accel, Z3, Z3, Z3, 0.0).a_enu_m_s2 is None
    with pytest.raises(SetpointRefused, match="yaw rate not taken"):
        position_target(M.MAV_FRAME_LOCAL_NED, 0, Z3, Z3, Z3, 0.0, 0.5)
    for rate in (0.0, math.nan):
        position_target(M.MAV_FRAME_LOCAL_NED, 0, Z3, Z3, Z3, 0.0, rate)
    position_target(M.MAV_FRAME_LOCAL_NED, M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE, Z3, Z3,
                    Z3, 0.0, 0.5)


def test_attitude_normalised_in_enu_flu_and_rates_in_flu():
    q_enu_flu = q_exp((0.1, -0.2, 0.3))
    q_wire = tuple(2.0 * c for c in q_enu_flu_to_ned_frd(q_enu_flu))
    t = attitude_target(0, q_wire, (0.1, 0.2, 0.3))
    assert q_angle(q_mul(q_conj(q_enu_flu), t.q_enu_flu)) < 1e-12
    assert t.omega_flu_rad_s == (0.1, -0.2, -0.3)
    rates_off = attitude_target(M.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE, q_wire, Z3)
    assert not rates_off.has_rates and rates_off.has_attitude
    no_att = attitude_target(M.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE, (0.0,) * 4, Z3)
    assert not no_att.has_attitude  # an ignored attitude is not checked


@pytest.mark.parametrize("q", [(0.0, 0.0, 0.0, 0.0), (0.1, 0.1, 0.1, 0.1), (math.nan, 1, 0, 0)])
def test_a_quaternion_far_from_unit_is_refused(q):
    with pytest.raises(SetpointRefused, match="not a unit quaternion"):
        attitude_target(0, q, Z3)
