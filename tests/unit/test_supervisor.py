"""The supervisor (`fcu/safety/supervisor.py`), the gate between the allocator and the actuators:
speeds only while armed and within [0, w_max], a non-finite command stopped with the last
finite tilts, whatever the arming state."""

from __future__ import annotations

import math

import pytest

from fcu.safety.supervisor import Supervisor

W_MAX = 1700.0
TILTS = (0.1, -0.2, 0.3, -0.4, 0.5, -0.6)


def test_armed_speeds_pass_clamped_to_zero_and_w_max_with_their_tilts():
    gate = Supervisor(6, W_MAX).gate(True, (-5.0, 0.0, 900.0, 1700.0, 1700.1, 5e3), TILTS)
    assert gate == ((0.0, 0.0, 900.0, 1700.0, 1700.0, 1700.0), TILTS, "")


def test_disarmed_no_rotor_turns_and_the_tilts_given_pass():
    gate = Supervisor(6, W_MAX).gate(False, (1000.0,) * 6, TILTS)
    assert gate == ((0.0,) * 6, TILTS, "")


@pytest.mark.parametrize("armed", [True, False])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("where", ["speed", "tilt"])
def test_a_non_finite_command_is_a_fault_with_zero_speeds_and_the_last_finite_tilts(
        armed, bad, where):
    sup = Supervisor(6, W_MAX, initial_tilt_rad=(0.05,) * 6)
    assert sup.gate(armed, (1000.0,) * 6, TILTS).fault == ""
    speeds, tilts = [1000.0] * 6, list(TILTS)
    (speeds if where == "speed" else tilts)[2] = bad
    gate = sup.gate(armed, tuple(speeds), tuple(-t for t in tilts))
    assert gate == ((0.0,) * 6, TILTS, "non-finite actuator command")
    assert sup.gate(armed, (1000.0,) * 6, TILTS).tilt_rad == TILTS  # held, not the bad one


def test_before_any_command_the_held_tilts_are_the_initial_ones():
    sup = Supervisor(6, W_MAX, initial_tilt_rad=(0.05,) * 6)
    assert sup.gate(True, (math.nan,) * 6, TILTS).tilt_rad == (0.05,) * 6
    assert Supervisor(6, W_MAX).gate(True, (math.nan,) * 6, TILTS).tilt_rad == (0.0,) * 6
