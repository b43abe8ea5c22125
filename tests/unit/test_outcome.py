"""Honest outcomes: the status of a run from what happened to the vehicle (common/outcome.py)
and the pipeline's failsafe reactions that feed it (fcu/pipeline.py)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import ConfigError, load_gains, load_scenario, load_vehicle
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from common.outcome import (
    CRASH,
    DIVERGED,
    DIVERGENCE_ATTITUDE_HOLD_S,
    DIVERGENCE_ATTITUDE_RAD,
    FAILSAFE,
    INFO,
    LIMIT,
    STATUSES,
    Event,
    attitude_held,
    classify,
    diverged,
    diverged_rows,
    touchdowns,
)
from fcu.pipeline import Pipeline
from fcu.stages import VehicleState
from gcs.report.metrics import build_metrics

ROOT = Path(__file__).resolve().parents[2]
HOVER_STATE = VehicleState((0.0, 0.0, 5.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                           (0.0, 0.0, 0.0))


def ev(t_s: float, kind: str, text: str = "x") -> Event:
    return Event(round(t_s * 1e6), 4, text, kind)


@pytest.mark.parametrize(("kwargs", "status"), [
    ({"reached_end": True, "events": [ev(0, INFO)]}, "completed"),
    ({"reached_end": True, "events": [ev(3, FAILSAFE, "hold")]}, "failsafe"),
    ({"reached_end": True, "events": [ev(3, FAILSAFE), ev(3, CRASH)]}, "crashed"),
    ({"reached_end": True, "events": [ev(3, DIVERGED)], "divergence_t_us": 3_000_000},
     "diverged"),
    ({"reached_end": True, "events": [ev(2, CRASH)], "divergence_t_us": 3_000_000},
     "crashed"),
    ({"reached_end": True, "events": [], "divergence_t_us": 1, "crash_t_us": 2}, "diverged"),
    ({"reached_end": True, "events": [ev(3, DIVERGED), ev(4, FAILSAFE)]}, "diverged"),
    ({"reached_end": True, "events": [ev(3, DIVERGED)], "crash_t_us": 3_500_000}, "diverged"),
    ({"reached_end": True, "events": [], "crash_t_us": 5_000_000}, "crashed"),
    ({"reached_end": False, "events": [], "stopped": "timeout"}, "timeout"),
    ({"reached_end": False, "events": [ev(1, FAILSAFE)], "stopped": "aborted"}, "aborted"),
    ({"reached_end": False, "events": []}, "aborted"),
    ({"reached_end": True, "events": [ev(2, LIMIT), ev(3, INFO)]}, "limited"),
    ({"reached_end": True, "events": [ev(2, LIMIT), ev(3, FAILSAFE)]}, "failsafe"),
    ({"reached_end": True, "events": [ev(2, LIMIT), ev(3, DIVERGED)]}, "diverged"),
    ({"reached_end": True, "events": [ev(2, LIMIT)], "divergence_t_us": 3_000_000},
     "diverged"),
    ({"reached_end": True, "events": [ev(2, LIMIT)], "crash_t_us": 3_000_000}, "crashed"),
    ({"reached_end": False, "events": [ev(2, LIMIT)], "stopped": "timeout"}, "timeout"),
    ({"reached_end": False, "events": [ev(2, LIMIT)]}, "aborted"),
])
def test_status_precedence(kwargs, status):
    """Given what happened, then exactly one status: divergence or crash first (whichever
    came first), then a stopped run, then any failsafe reaction, then a run cut short, then
    an actuator limit reported (limited), then completed."""
    kwargs.setdefault("divergence_t_us", None)
    assert classify(**kwargs).status == status and status in STATUSES


def test_a_failsafe_that_cleared_still_counts():
    out = classify(reached_end=True, events=[ev(4, FAILSAFE, "failsafe: GCS link lost: HOLD"),
                                             ev(6, INFO, "GCS link regained")],
                   divergence_t_us=None)
    assert out.status == "failsafe" and out.failsafe == "failsafe: GCS link lost: HOLD"


def test_a_limit_report_makes_a_finished_run_limited_and_says_which():
    """Given two limit reports and their clearing, then the run is limited, its reason the
    first report with its time and how many followed; the clearing alone is no limit."""
    out = classify(reached_end=True, divergence_t_us=None, events=[
        Event(1_500_000, 4, "tilt servo 2 rate-limited 0.1 s: 7.0 > 4 rad/s", LIMIT),
        Event(1_600_000, 4, "rotor 3 at speed limit 0.1 s: 2147 > 1700 rad/s", LIMIT),
        Event(1_900_000, 6, "actuator limits cleared", INFO)])
    assert out == ("limited", "", "actuator limit at t = 1.500 s: tilt servo 2 rate-limited "
                   "0.1 s: 7.0 > 4 rad/s (and 1 more)")
    assert classify(reached_end=True, divergence_t_us=None, events=[
        Event(1_900_000, 6, "actuator limits cleared", INFO)]).status == "completed"


def test_one_divergence_rule_scalar_and_rows():
    assert diverged(10.01, True, 10.0) and not diverged(9.99, True, 10.0)
    assert diverged(0.0, False, 10.0) and diverged(float("nan"), True, 10.0)
    p = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 10.5], [np.nan, 0.0, 0.0]])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    t_us = np.array([0, 2000, 4000])
    assert diverged_rows(p, q, np.zeros((3, 3)), q, 10.0, t_us=t_us).tolist() == \
        [False, True, True]


def _about_z(angle_rad: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(angle_rad / 2), np.zeros((len(angle_rad), 2)),
                            np.sin(angle_rad / 2)])


def test_attitude_bound_needs_its_hold_time():
    """Given an attitude error above the limit, then rows diverge only once it has stayed
    above for the hold time without a break (a peak is flown through); the position is
    exact throughout."""
    t_us = np.arange(0, 4_000_001, 2000)
    t = t_us * 1e-6
    limit, hold = DIVERGENCE_ATTITUDE_RAD, DIVERGENCE_ATTITUDE_HOLD_S
    err = np.where((t >= 1.0) & (t < 1.0 + 0.9 * hold), limit + 0.5, 0.0)  # a peak
    err = np.where(t >= 2.0, limit + 0.5, err)  # held from 2 s on
    err[np.searchsorted(t, 2.0 + 0.5 * hold)] = limit - 0.1  # a break: the clock restarts
    q_d = _about_z(np.zeros(len(t)))
    p = np.zeros((len(t), 3))
    rows = diverged_rows(p, _about_z(err), p, q_d, 10.0, t_us=t_us)
    first = int(np.argmax(rows))
    assert t[first] == pytest.approx(2.0 + 0.5 * hold + 0.002 + hold)
    assert np.all(rows[first:]) and not np.any(rows[:first])
    assert np.array_equal(rows, attitude_held(t_us, err, limit, hold))
    assert not np.any(diverged_rows(p, _about_z(err), p, q_d, 10.0, t_us=t_us,
                                    attitude_limit_rad=math.pi))


def _logs(t_s: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Truth and onboard logs of a hover at the origin, desired attitude level, truth
    attitude q: the position tracks exactly."""
    truth = np.zeros((len(t_s), len(TRUTH_COLUMNS)))
    onboard = np.zeros((len(t_s), len(ONBOARD_COLUMNS)))
    for log, columns in ((truth, TRUTH_COLUMNS), (onboard, ONBOARD_COLUMNS)):
        log[:, columns.index("time_us")] = np.round(t_s * 1e6)
    truth[:, [TRUTH_COLUMNS.index(c) for c in ("qw", "qx", "qy", "qz")]] = q
    onboard[:, ONBOARD_COLUMNS.index("qw")] = 1.0
    onboard[:, ONBOARD_COLUMNS.index("qdw")] = 1.0
    return truth, onboard


@pytest.mark.parametrize(("excursion_s", "status"), [(0.5, "completed"), (2.0, "diverged")])
def test_good_position_wrong_attitude_is_not_completed(excursion_s, status):
    """Given a run whose position tracks exactly but whose attitude is 2.5 rad off the
    desired one from 1 s on for `excursion_s`, then metrics.json's status is completed for a
    peak shorter than the hold time and diverged, on attitude, when the error is held: the
    status judges attitude as well as position."""
    scenario = dataclasses.replace(load_scenario(ROOT / "config/scenarios/case2_sine.toml"),
                                   duration_s=4.0)
    t = np.arange(0.0, 4.0 + 1e-9, 0.002)
    off = np.where((t >= 1.0) & (t < 1.0 + excursion_s), 2.5, 0.0)
    truth, onboard = _logs(t, _about_z(off))
    m = build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard, events=[],
                      wall_time_s=1.0, transport="in-process", lockstep=True)
    assert m["position_error_m"]["max"] == 0.0
    assert m["status"] == status
    if status == "diverged":
        assert m["divergence_t_s"] == pytest.approx(1.0 + DIVERGENCE_ATTITUDE_HOLD_S)
        assert m["status_reason"] == (f"diverged at t = {1.0 + DIVERGENCE_ATTITUDE_HOLD_S:.3f}"
                                      f" s: attitude error above {DIVERGENCE_ATTITUDE_RAD:g} "
                                      f"rad for {DIVERGENCE_ATTITUDE_HOLD_S:g} s")


def test_touchdown_speed_is_the_speed_before_contact():
    landed = np.array([1, 0, 0, 0, 1, 1, 0, 1], dtype=float)
    speed = np.array([0, 1.0, 2.0, 3.0, 0.0, 0.0, 0.4, 0.0])
    assert touchdowns(landed, speed) == [(4, 3.0), (7, 0.4)]


def _pipeline() -> Pipeline:
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    return Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500)


def test_state_loss_is_judged_on_the_flight_clock():
    """Given a state received at 0 s, when control steps run at 0.5 s then 1.2 s of the
    flight clock, then only the second (past COM_STATE_LOSS_T = 1 s) disarms, with a failsafe
    event and, the vehicle being in the air, a crash event."""
    pipe = _pipeline()
    pipe.on_state(0, HOVER_STATE, 0)
    assert pipe.arm()[0] == 0
    assert pipe.step(500_000).armed
    out = pipe.step(1_200_000)
    assert not out.armed and out.speed_rad_s == (0.0,) * 6
    kinds = [e.kind for e in pipe.events]
    assert FAILSAFE in kinds and CRASH in kinds
    assert classify(reached_end=True, events=pipe.events,
                    divergence_t_us=None).status == "crashed"


def test_lockstep_states_never_age():
    """Given a state with every control period (lockstep), however long the wall clock
    stands still between them, then no failsafe: the pipeline has no wall clock."""
    pipe = _pipeline()
    pipe.on_state(0, HOVER_STATE, 0)
    pipe.arm()
    for k in range(1, 2000):
        t = k * 2000
        pipe.on_state(t, HOVER_STATE, t)
        assert pipe.step(t).armed
    assert all(e.kind == INFO for e in pipe.events)


def test_divergence_disarms_as_divergence_not_crash():
    pipe = _pipeline()
    pipe.on_state(0, HOVER_STATE, 0)
    pipe.arm()
    pipe.step(0)
    far = HOVER_STATE._replace(p_enu_m=(11.0, 0.0, 5.0))
    pipe.on_state(2000, far, 2000)
    out = pipe.step(2000)
    assert not out.armed and out.result is not None
    kinds = [e.kind for e in pipe.events]
    assert DIVERGED in kinds and CRASH not in kinds
    assert pipe.failsafe == "diverged"


def test_the_scenarios_attitude_rule_is_the_one_judged(tmp_path):
    """Given a scenario that sets divergence_attitude_rad = 3 and a hold of 0.5 s, then a
    2.5 rad excursion held 2 s completes, a 3.1 rad one held 0.6 s diverges 0.5 s after it
    starts and says the scenario's figures; out-of-range keys are refused at load."""
    source = (ROOT / "config/scenarios/case2_sine.toml").read_text()
    path = tmp_path / "case2_sine.toml"
    source = source.replace('"../', f'"{ROOT}/config/')
    path.write_text("divergence_attitude_rad = 3.0\ndivergence_attitude_hold_s = 0.5\n"
                    + source)
    scenario = dataclasses.replace(load_scenario(path), duration_s=4.0)
    assert (scenario.divergence_attitude_rad, scenario.divergence_attitude_hold_s) == (3.0, 0.5)
    t = np.arange(0.0, 4.0 + 1e-9, 0.002)
    for size, length, status in ((2.5, 2.0, "completed"), (3.1, 0.6, "diverged")):
        off = np.where((t >= 1.0) & (t < 1.0 + length), size, 0.0)
        truth, onboard = _logs(t, _about_z(off))
        m = build_metrics(scenario, TRUTH_COLUMNS, truth, ONBOARD_COLUMNS, onboard, events=[],
                          wall_time_s=1.0, transport="in-process", lockstep=True)
        assert m["status"] == status, (size, length)
    assert m["divergence_t_s"] == pytest.approx(1.5)
    assert m["status_reason"].endswith("attitude error above 3 rad for 0.5 s")
    for key, value in (("divergence_attitude_rad", "3.5"), ("divergence_attitude_hold_s", "-1")):
        path.write_text(f"{key} = {value}\n" + source)
        with pytest.raises(ConfigError, match=key):
            load_scenario(path)
