"""The real-time loop's deadlines (`fcu.edge.deadlines`): a step more than half a period late is a
miss, the periods it passed over are misses too, the grid keeps its phase, and the first
misses are kept with when and how late."""

from __future__ import annotations

import pytest

from fcu.edge.deadlines import KEPT, Deadlines

PERIOD = 0.002


def test_a_step_on_time_or_a_little_late_misses_nothing_and_keeps_the_grid():
    d = Deadlines(PERIOD)
    assert d.step(10.0, 10.0, 0.0) == pytest.approx(10.002)
    assert d.step(10.0029, 10.002, 0.0) == pytest.approx(10.004)  # 0.9 ms: no miss
    assert d.misses == 0 and d.first == []


def test_a_late_step_misses_its_period_and_those_it_passed_over_on_the_same_grid():
    d = Deadlines(PERIOD)
    assert d.step(10.0011, 10.0, 9.0) == pytest.approx(10.002)  # 1.1 ms late: one miss
    assert d.misses == 1 and d.first == [(1.0011, 1.1)]
    assert d.step(10.0075, 10.002, 9.0) == pytest.approx(10.008)  # 5.5 ms: 2 passed over
    assert d.misses == 4 and d.first[-1] == (1.0075, 5.5)


def test_only_the_first_misses_are_kept():
    d = Deadlines(PERIOD)
    due = 0.0
    for _ in range(KEPT + 5):
        due = d.step(due + 0.0015, due, 0.0)
    assert d.misses == KEPT + 5 and len(d.first) == KEPT
