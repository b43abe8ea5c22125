"""HOLD's brake and OFFBOARD's start beside the control loop (`fcu.modes.shaping`): where
the work runs beside, a step never plans an approach (`fcu.reference.approach.plan`); a reference
that was moving coasts until its plan, made ANCHOR_LEAD_US ahead, is taken in at its time, and
flies on continuously; a plan that does not come is made in the loop after COAST_MAX_US."""

from __future__ import annotations

import itertools
import math
import pickle
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from common.wire.mav_enums import MAV_RESULT
from common.wire.modes import Mode
from fcu.edge.setpoint_wire import position_target
from fcu.modes import offboard
from fcu.modes.shaping import ANCHOR_LEAD_US, COAST_MAX_US
from fcu.reference import approach
from fcu.stages import Reference
from fcu.work import Done, Outcome, Work
from tests.unit.test_work import airborne_commander

PERIOD_US = 2000
POSITION_ONLY = 0b0000_1101_1111_1000


class HeldWork(Work):
    """Jobs run when the test releases them (work beside the loop that takes as long as
    the test wants); `planned_in_jobs` / `planned_in_steps` count `approach.plan` calls
    made inside a job and outside any (in a control step)."""

    kind = "held"

    def __init__(self) -> None:
        super().__init__()
        self.held: list[tuple[Callable[..., Any], tuple[Any, ...], Done]] = []
        self.in_job = False

    @property
    def pending(self) -> int:
        return len(self.held) + len(self._finished)

    def _submit(self, fn: Callable[..., Any], args: tuple[Any, ...], done: Done,
                warm_up: bool) -> None:
        self.held.append((fn, args, done))

    def names(self) -> list[str]:
        return [fn.__name__ for fn, _, _ in self.held]

    def release(self) -> int:
        for fn, args, done in self.held:
            self.in_job = True
            try:
                self._finished.append((done, Outcome(fn(*args))))
            finally:
                self.in_job = False
        self.held = []
        return self.take()


@contextmanager
def counted_plans(work: HeldWork) -> Iterator[dict[str, int]]:
    """`approach.plan` counted by where it ran: in a job, or in a control step."""
    counts = {"job": 0, "step": 0}
    real = approach.plan

    def plan(*args: Any, **kwargs: Any) -> Any:
        counts["job" if work.in_job else "step"] += 1
        return real(*args, **kwargs)

    mp = pytest.MonkeyPatch()
    mp.setattr(approach, "plan", plan)
    try:
        yield counts
    finally:
        mp.undo()


def _fly(c: Any, t_us: int) -> Reference:
    """One control step's reference, kept as the pipeline keeps it."""
    ref: Reference = c.reference(t_us)
    c.last_ref = ref
    return ref


def _moving_north(work: Work) -> tuple[Any, int]:
    """OFFBOARD towards a set-point 20 m north (ENU y), 1.5 s under way: the reference
    moves at POSCTL's speed. (the commander, the flight clock)"""
    c = airborne_commander()
    c.work = work
    assert c.offboard_position(0.0, position_target(1, POSITION_ONLY, (20.0, 0.0, -2.0),
                                                    (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    t = 0
    for _ in range(750):
        t += PERIOD_US
        _fly(c, t)
        if isinstance(work, HeldWork):
            work.release()
    assert math.hypot(*c.last_ref.v_enu_m_s) > 1.0
    return c, t


def _coasting(ref: Reference, start: Reference, tau_s: float) -> bool:
    """`ref` is `start` extrapolated tau_s at its acceleration (a coast)."""
    return ref.v_enu_m_s == pytest.approx(
        [v + a * tau_s for v, a in zip(start.v_enu_m_s, start.a_enu_m_s2, strict=True)],
        abs=1e-9) and ref.a_enu_m_s2 == start.a_enu_m_s2


def _speed_steps(path: list[Reference]) -> float:
    """The largest change of velocity between two steps, m/s."""
    return max(math.dist(a.v_enu_m_s, b.v_enu_m_s) for a, b in itertools.pairwise(path))


def test_hold_from_a_moving_reference_coasts_until_its_brake_planned_beside_is_in():
    """Given OFFBOARD moving north at speed with the work beside the loop, when HOLD is
    asked, then no step plans: the first submits HOLD's brake and the reference coasts on
    at its velocity until ANCHOR_LEAD_US later, then brakes along the plan to rest,
    continuous throughout, and holds where the brake asked at the lead would (a little
    ahead of where the brake made in the step holds)."""
    work = HeldWork()
    c, t = _moving_north(work)
    flown = c.last_ref
    with counted_plans(work) as plans:
        assert c.set_mode(Mode.HOLD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
        asked = t + PERIOD_US
        path = [c.last_ref]
        for k in range(1, 4):  # the brake under way beside: the reference coasts
            path.append(_fly(c, t + PERIOD_US * k))
        assert work.names() == ["brake_ahead"] and plans == {"job": 0, "step": 0}
        # from the first step in HOLD on (it starts where the last step's reference was)
        assert all(_coasting(r, flown, k * PERIOD_US * 1e-6) for k, r in enumerate(path[1:]))
        work.release()
        assert plans == {"job": 1, "step": 0}
        for k in range(4, 3000):
            ref = _fly(c, t + PERIOD_US * k)
            if t + PERIOD_US * k < asked + ANCHOR_LEAD_US:  # not before its time
                assert _coasting(ref, flown, (k - 1) * PERIOD_US * 1e-6)
            path.append(ref)
        assert plans["step"] == 0 and work.held == []
    assert path[-1].v_enu_m_s == (0.0, 0.0, 0.0) and c.modes.brake.hold.p_enu_m == path[-1].p_enu_m
    # MPC_ACC_HOR 5 m/s^2 at most per 2 ms step: no jump where the brake was taken in
    assert _speed_steps(path) <= 5.0 * PERIOD_US * 1e-6 + 1e-9
    lim, env = offboard.limits(c.flight.sticks), c.modes._envelope()
    _, held = offboard.brake_ahead(offboard.coast(asked, flown), asked + ANCHOR_LEAD_US, lim,
                                   env)
    assert held == c.modes.brake.hold  # the brake from where the coast is at the lead
    # the brake made in the step rests a little behind (asked 10 ms sooner, accelerating)
    _, held_inline = offboard.brake(asked, flown, lim, env)
    assert 0.0 < c.modes.brake.hold.p_enu_m[1] - held_inline.p_enu_m[1] < 0.1


def test_a_brake_that_does_not_come_is_planned_in_the_loop_after_coast_max_us():
    """Given HOLD's brake submitted beside the loop and never done (a worker late or
    stuck), then the reference coasts COAST_MAX_US, is braked in the loop then (counted in
    inline_plans and said once), and comes to rest; the late result is then ignored."""
    work = HeldWork()
    c, t = _moving_north(work)
    assert c.set_mode(Mode.HOLD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    c.events.clear()
    path = [c.last_ref]
    for k in range(1, 2000):
        path.append(_fly(c, t + PERIOD_US * k))
        if k * PERIOD_US < COAST_MAX_US:
            assert _coasting(path[-1], path[0], (k - 1) * PERIOD_US * 1e-6)
    assert c.modes.ahead.inline_plans == 1 and [e.text for e in c.events] == \
        ["work late: planned in the loop"]
    work.release()  # the stale brake: dropped
    for k in range(2000, 3000):
        path.append(_fly(c, t + PERIOD_US * k))
    assert path[-1].v_enu_m_s == (0.0, 0.0, 0.0)
    assert _speed_steps(path) <= 5.0 * PERIOD_US * 1e-6 + 1e-9


def test_offboard_entered_moving_anchors_its_sample_from_the_coast_beside_the_loop():
    """Given HOLD braking from speed beside the loop, when OFFBOARD is entered again with
    a new set-point (2 m east), then no step plans: the reference coasts from the one
    flown, the sample is anchored beside from the coast, and the vehicle's reference
    reaches it continuously."""
    work = HeldWork()
    c, t = _moving_north(work)
    with counted_plans(work) as plans:
        assert c.set_mode(Mode.HOLD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
        path = [c.last_ref]
        for k in range(1, 3):
            path.append(_fly(c, t + PERIOD_US * k))
        t += 2 * PERIOD_US
        assert c.offboard_position(0.0, position_target(1, POSITION_ONLY, (0.0, 2.0, -2.0),
                                                        (0.0,) * 3, (0.0,) * 3, 0.0))[0]
        assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
        for k in range(1, 4000):
            path.append(_fly(c, t + PERIOD_US * k))
            work.release()
        assert plans["step"] == 0 and plans["job"] >= 2
    jobs = [name for name, _ in work.history]
    assert jobs[jobs.index("brake_ahead") + 1] == "advance", jobs  # the sample, from the coast
    assert math.dist(path[-1].p_enu_m, (2.0, 0.0, 2.0)) < 1e-6
    assert _speed_steps(path) <= 5.0 * PERIOD_US * 1e-6 + 1e-9


def test_start_ahead_is_the_start_from_where_the_coast_is_then():
    """offboard.start_ahead and brake_ahead plan from the coast's reference at their time:
    the same as `start` and `brake` given that reference."""
    ref = Reference((1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), (1.5, -0.5, 0.2), (0.3, 0.0, 0.0),
                    (0.0, 0.0, 0.4), (0.0, 0.0, 0.0))
    lim = offboard.limits(airborne_commander().flight.sticks)
    s = offboard.coast(1000, ref)
    assert offboard.moving(ref) and not offboard.moving(
        Reference(ref.p_enu_m, ref.q_enu_flu, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3))
    later = offboard.advance(s, 11_000, None, lim)[1]
    assert later.p_enu_m[0] == pytest.approx(1.0 + 1.5 * 0.01 + 0.5 * 0.3 * 1e-4, abs=1e-12)
    started, at = offboard.start_ahead(s, 11_000, lim)
    assert at == later and started.plan is not None  # (pickled: the plans hold arrays)
    assert pickle.dumps(started) == pickle.dumps(offboard.start(11_000, later, lim))
    assert pickle.dumps(offboard.brake_ahead(s, 11_000, lim)) == \
        pickle.dumps(offboard.brake(11_000, later, lim))


def test_the_lead_grows_after_a_late_plan_and_comes_back_after_plans_on_time():
    """Given HOLD's brake that came 20 ms after it was asked (10 ms after its time), then it
    is not flown, the next is asked twice that time ahead (so a machine that slow is in
    time), and that one, in time, is flown; each plan on time brings the lead a quarter of
    the way back to ANCHOR_LEAD_US."""
    work = HeldWork()
    c, t = _moving_north(work)
    assert c.set_mode(Mode.HOLD, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    asked = t + PERIOD_US
    for k in range(1, 12):
        _fly(c, t + PERIOD_US * k)
    assert len(work.held) == 1 and work.held[0][1][1] == asked + ANCHOR_LEAD_US
    work.release()  # at t + 11 periods: 20 ms after it was asked, past its time
    ahead = c.modes.ahead
    assert ahead.late_anchors == 1 and ahead.lead_us == 2 * (t + 11 * PERIOD_US - asked)
    again = t + 12 * PERIOD_US
    _fly(c, again)
    assert work.held[0][1][1] == again + c.modes.ahead.lead_us  # asked again, further ahead
    work.release()
    assert ahead.late_anchors == 1 and ahead.lead_us == 40_000 - (40_000 - ANCHOR_LEAD_US) // 4
    for k in range(13, 3000):
        ref = _fly(c, t + PERIOD_US * k)
    assert c.modes.ahead.inline_plans == 0 and ref.v_enu_m_s == (0.0, 0.0, 0.0)
