"""The supervisor (`fcu/safety/supervisor.py`), the gate between the allocator and the actuators:
speeds only while armed and within [0, w_max], a non-finite command stopped with the last
finite tilts, whatever the arming state."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fcu.safety.supervisor import Supervisor

W_MAX = 1700.0
TILTS = (0.1, -0.2, 0.3, -0.4, 0.5, -0.6)


def test_armed_speeds_pass_clamped_to_zero_and_w_max_with_their_tilts():
    gate = Supervisor(6, W_MAX).gate(True, (-5.0, 0.0, 900.0, 1700.0, 1700.1, 5e3), TILTS)
    assert gate == ((0.0, 0.0, 900.0, 1700.0, 1700.0, 1700.0), TILTS, "")


def test_armed_speeds_at_the_edges_of_zero_and_w_max():
    """The bounds hold to the last bit: the smallest negative speed is 0, the next float past
    w_max is w_max, and the floats just inside either bound pass unchanged."""
    below, above = math.nextafter(0.0, -1.0), math.nextafter(W_MAX, math.inf)
    inside_max, inside_zero = math.nextafter(W_MAX, 0.0), math.nextafter(0.0, 1.0)
    gate = Supervisor(6, W_MAX).gate(True, (below, -0.5, inside_zero, inside_max, W_MAX, above),
                                     TILTS)
    assert gate == ((0.0, 0.0, inside_zero, inside_max, W_MAX, W_MAX), TILTS, "")


FINITE = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(armed=st.booleans(), speeds=st.lists(FINITE, min_size=6, max_size=6),
       tilts=st.lists(FINITE, min_size=6, max_size=6))
def test_any_finite_command_turns_rotors_only_when_armed_within_zero_and_w_max(
        armed, speeds, tilts):
    """Given any finite command, then the speeds are within [0, w_max], the command's own
    where it is inside, zero unless armed; the tilts given pass either way, no fault."""
    gate = Supervisor(6, W_MAX).gate(armed, tuple(speeds), tuple(tilts))
    assert all(0.0 <= w <= W_MAX for w in gate.speed_rad_s)
    expected = [min(max(w, 0.0), W_MAX) if armed else 0.0 for w in speeds]
    assert list(gate.speed_rad_s) == expected
    assert gate.tilt_rad == tuple(tilts) and gate.fault == ""


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
