"""OFFBOARD attitude steps and HOLD at speed, on both vehicle files, with the set-point limits
fitted to every actuator (`manual.fit_envelope`, fcu.setpoint_envelope): no commanded tilt
moves faster than the servo's rate limit for more than COM_ACT_RATE_T (0.1 s), no rotor is
commanded at w_max for more than 0.1 s, and the vehicle tracks the shaped reference within
5 cm and 3 deg. Before the fit judged tilts, a 170 deg roll on the tilted preset outran the
servos for 0.23 s, and HOLD from 10 m/s on the planar one for 0.15 s, lagging 25 cm."""

from __future__ import annotations

import math

import pytest

from common.modes import Mode
from gcs.vehicle_link import PoseTarget

from .setpoint_flights import VEHICLES, fly_hold_at_speed, fly_pose_step

_AXIS = (0.48, -0.6, 0.64)  # a fixed "random" axis (unit), NED/FRD
_HALF = math.radians(85.0)  # a 170 deg rotation


def _turned(axis: tuple[float, float, float]) -> PoseTarget:
    s = math.sin(_HALF)
    return PoseTarget((0.0, 0.0, -5.0), (math.cos(_HALF), axis[0] * s, axis[1] * s,
                                         axis[2] * s))


def _within_envelope(f: dict) -> None:
    assert f["armed"], f
    assert f["tilt_over_s"] <= 0.1, f
    assert f["rotor_over_s"] <= 0.1, f
    assert f["track_m"] <= 0.05 and f["track_deg"] <= 3.0, f


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), _AXIS],
                         ids=["x", "y", "random"])
def test_a_170_deg_offboard_rotation_keeps_every_actuator_in_its_envelope(vehicle, axis):
    """Given a level hover, when OFFBOARD streams the same position turned 170 deg about the
    body axis, then the tilts, rotors and tracking stay within their bounds and the pose is
    reached (5 cm, 1 deg) and held."""
    f = fly_pose_step(vehicle, (0.0, 0.0, 5.0), _turned(axis), 25.0)
    _within_envelope(f)
    assert f["mode"] == Mode.OFFBOARD and f["reached_s"] < 24.0, f
    assert f["error_m"] < 0.01 and f["error_deg"] < 0.5, f


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_hold_at_10_m_s_brakes_within_every_actuator(vehicle):
    """Given the vehicle flying OFFBOARD at 10 m/s, when HOLD comes, then it brakes to the
    stopping pose with the tilts, rotors and tracking within their bounds, and rests there
    (1 cm)."""
    f = fly_hold_at_speed(vehicle, 10.0, 40.0, 45.0)
    assert f["speed_at_hold"] > 9.9, f
    _within_envelope(f)
    assert f["mode"] == Mode.HOLD and f["error_m"] < 0.01, f
