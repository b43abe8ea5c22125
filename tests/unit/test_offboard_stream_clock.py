"""Offboard set-point loss on the FCU's clock (`fcu.modes.offboard_stream`): the wall clock in
real time, as PX4; in lockstep a sample is as old as the lesser of its wall-clock and
flight-clock ages, so machine load (simulated time slowed with the ground station) and a
run faster than real time (a wall-clock stream thinned on the flight clock) lose nothing."""

from __future__ import annotations

from fcu.modes.offboard_stream import OffboardSetpoint, PositionTarget
from fcu.safety.failsafe import offboard_lost

T = 1.0  # COM_OF_LOSS_T
TARGET = PositionTarget((0.0, 0.0, 2.0))


class Clocks:
    def __init__(self) -> None:
        self.wall = 100.0
        self.flight = 0.0

    def advance(self, wall_s: float, flight_s: float) -> None:
        self.wall += wall_s
        self.flight += flight_s


def _lockstep(c: Clocks) -> OffboardSetpoint:
    sp = OffboardSetpoint(flight_clock=lambda: c.flight, wall_clock=lambda: c.wall)
    assert sp.take_position(c.wall, TARGET, 100.0) == ""
    return sp


def _lost(sp: OffboardSetpoint, c: Clocks) -> bool:
    """As the FCU's callers judge it (the pipeline's failsafe, the mode refusal): both ways
    agree."""
    by_received = offboard_lost(c.wall, sp.received_s, T)
    assert by_received == sp.lost(c.wall, T)
    return by_received


def test_real_time_is_judged_on_the_wall_clock_as_px4_does():
    sp = OffboardSetpoint()
    sp.take_position(100.0, TARGET, 100.0)
    assert sp.received_s == 100.0
    assert not sp.lost(100.9, T) and sp.lost(101.1, T)


def test_a_starved_machine_slowing_simulated_time_loses_nothing():
    c = Clocks()
    sp = _lockstep(c)
    c.advance(wall_s=3.0, flight_s=0.2)  # the station starved 3 s, the flight flew 0.2 s
    assert not _lost(sp, c)


def test_a_run_faster_than_real_time_loses_nothing_of_a_wall_clock_stream():
    c = Clocks()
    sp = _lockstep(c)
    c.advance(wall_s=0.3, flight_s=1.5)
    assert not _lost(sp, c)


def test_a_stream_that_stopped_is_lost_on_both_clocks():
    c = Clocks()
    sp = _lockstep(c)
    c.advance(wall_s=1.2, flight_s=1.2)
    assert _lost(sp, c)
    sp.take_position(c.wall, TARGET, 100.0)  # it comes back
    assert not _lost(sp, c)


def test_before_the_flight_starts_the_wall_clock_alone_judges():
    """Simulated time stands still until the flight starts: a stream that stopped long ago
    is no stream for entering OFFBOARD."""
    c = Clocks()
    sp = _lockstep(c)
    c.advance(wall_s=0.5, flight_s=0.0)
    assert not _lost(sp, c)
    c.advance(wall_s=5.0, flight_s=0.0)
    assert _lost(sp, c)


def test_no_sample_yet_is_lost_on_either_clock():
    c = Clocks()
    sp = OffboardSetpoint(flight_clock=lambda: c.flight, wall_clock=lambda: c.wall)
    assert sp.lost(c.wall, T) and offboard_lost(c.wall, sp.received_s, T)
