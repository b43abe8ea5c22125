"""The random-mission generator (benchmarks/random_mission_gen.py) and the campaign's error
measure (benchmarks/random_missions.py): determinism, the stated bounds, every item kind."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.random_mission_gen import (
    DEFAULT,
    FIGURE_EIGHT,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    POSE_KEYFRAME,
    item_kind,
    leg_lengths_m,
    random_cruise_speed,
    random_mission,
)
from benchmarks.random_missions import reason_kind, tracking_errors, violations
from common.logs.columns import ONBOARD_COLUMNS, TRUTH_COLUMNS
from fcu.control.dualquat import q_conj, q_exp, q_mul

DRAWS = 200


def _missions(seed: int = 0, n: int = DRAWS):
    rng = np.random.default_rng(seed)
    return [random_mission(rng) for _ in range(n)]


def test_same_seed_same_mission_other_seed_other():
    a, b, c = _missions(3, 5), _missions(3, 5), _missions(4, 5)
    same = [[tuple(math.nan if math.isnan(v) else v for v in it) for it in m] for m in a]
    again = [[tuple(math.nan if math.isnan(v) else v for v in it) for it in m] for m in b]
    assert repr(same) == repr(again)
    assert repr(a) != repr(c)


def test_structure_and_bounds():
    lands = 0
    for items in _missions():
        assert [it.seq for it in items] == list(range(len(items)))
        first = items[0]
        assert first.command == NAV_TAKEOFF and first.param2 == 0.0
        assert 1.0 <= -first.z <= 5.0
        assert all(it.command != NAV_TAKEOFF for it in items[1:])
        assert all(it.command != NAV_LAND for it in items[:-1])
        lands += items[-1].command == NAV_LAND
        draws = [it for it in items[1:] if it.command in (NAV_WAYPOINT, POSE_KEYFRAME,
                                                          FIGURE_EIGHT)]
        assert 2 <= len(draws) <= 12
        p = (0.0, 0.0, first.z)
        for it in items[1:]:
            if it.command in (NAV_WAYPOINT, POSE_KEYFRAME):
                leg = math.dist(p, (it.x_m, it.y_m, it.z))
                assert 0.2 - 1e-3 <= leg <= 30.0 + 1e-3
                assert -it.z >= 0.5 - 1e-9
                assert math.hypot(it.x_m, it.y_m) <= DEFAULT.max_radius_m
                p = (it.x_m, it.y_m, it.z)
            if it.command == NAV_WAYPOINT:
                assert 0.0 <= it.param1 <= 2.0
                assert math.isnan(it.param4) or -180.0 <= it.param4 < 180.0
            if it.command == NAV_LOITER_TIME:  # a keyframe's hold, where it ended
                assert (it.x_m, it.y_m, it.z) == p and 0.05 <= it.param1 <= 2.0
            if it.command == POSE_KEYFRAME:
                assert 0.5 <= it.param1 <= 10.0
                assert math.sqrt(it.param2**2 + it.param3**2 + it.param4**2) <= math.pi + 1e-9
            if it.command == FIGURE_EIGHT:
                assert 0.2 <= it.param1 <= 2.0 and 5.0 <= it.param2 <= 30.0
                assert 0.1 <= math.sqrt(it.param3**2 + it.param4**2 + it.z**2) <= 1.0
    assert 0.4 * DRAWS < lands < 0.6 * DRAWS


def test_every_kind_appears_and_yaw_both_ways():
    missions = _missions()
    kinds = {item_kind(it) for m in missions for it in m}
    assert kinds == {"takeoff", "waypoint", "hold", "keyframe", "figure", "land"}
    yaws = [it.param4 for m in missions for it in m if it.command == NAV_WAYPOINT]
    assert any(math.isnan(y) for y in yaws) and any(not math.isnan(y) for y in yaws)
    legs = [length for m in missions for seq, length in leg_lengths_m(m)
            if m[seq].command == NAV_WAYPOINT]
    assert min(legs) < 0.4 and max(legs) > 15.0  # log-uniform over 0.2..30 m


def test_keyframe_turns_at_most_180_deg_from_the_attitude_before():
    """The generator's attitude bookkeeping matches the executor's: the keyframe's turn from
    the previous item's planned attitude is the drawn one, <= 180 deg, and not always 0."""
    from fcu.mission.executor import MissionExecutor
    from fcu.mission.limits import MissionLimits

    turns = []
    for items in _missions(1, 60):
        ex = MissionExecutor(items, MissionLimits())
        ex.start(0.0, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
        for seq, t0, t1 in ex.schedule:
            if items[seq].command == POSE_KEYFRAME:
                q0 = ex.sample(t0 - 1e-6).q_enu_flu if t0 > 0 else (1.0, 0.0, 0.0, 0.0)
                q1 = ex.sample(t1 - 1e-9).q_enu_flu
                d = q_mul(q_conj(q0), q1)
                turns.append(2.0 * math.degrees(math.acos(min(1.0, abs(d[0])))))
    assert turns and max(turns) <= 180.0 + 1e-3 and max(turns) > 120.0
    assert min(turns) < 30.0
    assert abs(float(np.mean(turns)) - 90.0) < 15.0  # uniform in [0, 180] deg


def test_cruise_speed_log_uniform_bounds():
    rng = np.random.default_rng(0)
    v = np.array([random_cruise_speed(rng) for _ in range(2000)])
    assert v.min() >= 0.2 and v.max() <= 15.0
    assert abs(np.median(np.log(v)) - 0.5 * (math.log(0.2) + math.log(15.0))) < 0.15


def _rows(n: int, columns: tuple[str, ...], step_us: int, **values: float) -> np.ndarray:
    rows = np.zeros((n, len(columns)))
    rows[:, columns.index("time_us")] = np.arange(n) * step_us
    for name, v in values.items():
        rows[:, columns.index(name)] = v
    return rows


def test_tracking_errors_match_on_time_and_skip_the_ground():
    truth = _rows(200, TRUTH_COLUMNS, 1000, qw=1.0, pz=2.0)
    onboard = _rows(100, ONBOARD_COLUMNS, 2000, qw=1.0, qdw=1.0, pdz=2.0, pz=2.0, armed=1.0)
    truth[truth[:, 0] == 1000, TRUTH_COLUMNS.index("px")] = 9.0  # no onboard row at 1 ms
    truth[truth[:, 0] == 40000, TRUTH_COLUMNS.index("px")] = 0.03  # 3 cm at 40 ms
    q = q_exp((0.0, 0.0, math.radians(2.0)))  # 2 deg at 60 ms
    truth[truth[:, 0] == 60000, 7:11] = q
    truth[truth[:, 0] == 80000, TRUTH_COLUMNS.index("landed")] = 1.0
    truth[truth[:, 0] == 80000, TRUTH_COLUMNS.index("px")] = 1.0  # on the ground: ignored
    err = tracking_errors(truth, onboard, 10000)
    assert err["pos_err_m"] == pytest.approx(0.03)
    assert err["att_err_deg"] == pytest.approx(2.0)
    assert err["est_pos_err_m"] == pytest.approx(0.03)
    assert tracking_errors(truth, onboard, 50000)["pos_err_m"] == pytest.approx(0.0)


def test_violations():
    ok = {"status": "completed", "status_reason": "", "pos_err_m": 0.049, "att_err_deg": 2.9,
          "monitor_events": []}
    assert violations(ok) == []
    for change in ({"pos_err_m": 0.051}, {"att_err_deg": 3.1}, {"status": "crashed"},
                   {"pos_err_m": math.nan}, {"monitor_events": ["rotor 2 rate-limited"]}):
        assert len(violations({**ok, **change})) == 1, change


def test_reason_kinds():
    assert reason_kind("item 3: tilt servo 2 needs 13.1 rad/s, limit 2.0 (50% of 4.0): "
                       "lengthen p1 to 2.31 s") == "tilt servo rate"
    assert reason_kind("item 1: rotor 4 needs 1400 rad/s, limit 1260 (90% of 1400): "
                       "lengthen p2 to 9.00 s") == "rotor speed"
    assert reason_kind("item 1: rotor 4 must slow at 900 rad/s^2, its lag allows 500: "
                       "lengthen p1 to 3.00 s") == "rotor rate"
    assert reason_kind("item 2: beyond the geofence (1200 m > 1000 m)") == "geofence"
