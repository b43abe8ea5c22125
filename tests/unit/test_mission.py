"""Mission executor (fcu/mission/): analytic derivatives, Case I equivalence, events,
validation, set_current, right-hand limits at segment boundaries."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import fcu.mission.codes as mission_mod
from common.config.scenario import load_scenario
from common.frames import enu_to_ned, ned_to_enu, q_enu_flu_to_ned_frd, q_ned_frd_to_enu_flu
from common.wire.mav_enums import MAV_MISSION_RESULT
from common.wire.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import MissionItem, local_xy
from fcu.control.dualquat import q_angle, q_conj, q_exp, q_mul, q_norm, q_rotate_inv
from fcu.mission import validation
from fcu.mission.executor import MissionEvent, MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.segments import level_attitude
from fcu.mission.validation import check_mission, refusal, validate_mission
from fcu.reference.trajectory import FigureEight, make_trajectory
from gcs.run.scenario_mission import scenario_mission

M = MAV
ROOT = Path(__file__).resolve().parents[2]
CASE1 = ROOT / "config/scenarios/case1_figure8.toml"
LIMITS = MissionLimits()
NAN = math.nan
H = 1e-4  # finite-difference step, s


def item(seq: int, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0,
         p4: float = 0.0, north: float = 0.0, east: float = 0.0, z: float = 0.0,
         frame: int = M.MAV_FRAME_LOCAL_NED) -> MissionItem:
    return MissionItem(seq, frame, command, int(seq == 0), 1, p1, p2, p3, p4, local_xy(north),
                       local_xy(east), z)


def renumber(items: list[MissionItem]) -> list[MissionItem]:
    return [it.with_seq(i) for i, it in enumerate(items)]


def started(items, t0: float = 0.0, p=(0.0, 0.0, 0.0), q=(1.0, 0.0, 0.0, 0.0),
            limits: MissionLimits = LIMITS) -> MissionExecutor:
    ex = MissionExecutor(renumber(list(items)), limits)
    ex.start(t0, p, q)
    return ex


def max_abs_diff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))))


# ----------------------------------------------------------------------------------------
# Wire numbers
# ----------------------------------------------------------------------------------------


def test_mavlink_numbers_match_pymavlink():
    """Given the numbers fcu.mission writes out, then they are pymavlink's common dialect."""
    for name in dir(mission_mod):
        if name.startswith(("MAV_MISSION_", "MAV_FRAME_", "MAV_CMD_NAV_")):
            assert getattr(mission_mod, name) == getattr(M, name), name
    assert mission_mod.MAV_CMD_POSE_KEYFRAME == MAV_CMD_POSE_KEYFRAME == 31000
    assert mission_mod.MAV_CMD_FIGURE_EIGHT == MAV_CMD_FIGURE_EIGHT == 31001


# ----------------------------------------------------------------------------------------
# Case I: the mission is the trajectory
# ----------------------------------------------------------------------------------------


def test_case1_mission_items():
    """Given Case I, then the mission is takeoff, loiter, figure (axis in NED), loiter."""
    items = scenario_mission(load_scenario(CASE1))
    assert [it.command for it in items] == [M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LOITER_TIME,
                                            MAV_CMD_FIGURE_EIGHT, M.MAV_CMD_NAV_LOITER_TIME]
    assert [it.seq for it in items] == [0, 1, 2, 3]
    assert [it.current for it in items] == [1, 0, 0, 0]
    assert all(it.frame == M.MAV_FRAME_LOCAL_NED and it.autocontinue == 1 for it in items)
    assert items[0].z == -5.0 and items[0].param2 == 10.0 and math.isnan(items[0].param4)
    assert items[1].param1 == 10.0 and items[3].param1 == 20.0
    fig = items[2]
    assert (fig.param1, fig.param2, fig.param3, fig.param4, fig.z) == (5.0, 120.0, 2.0, 1.0,
                                                                         -3.0)
    assert validate_mission(items, LIMITS) == (M.MAV_MISSION_ACCEPTED, None)


def test_case1_equivalence_every_control_step():
    """Given the Case I mission started at t = 0 from the origin, level, then its reference
    equals FigureEight's to 1e-9 in every field at every 500 Hz step of the 160 s run."""
    scenario = load_scenario(CASE1)
    ex = started(scenario_mission(scenario))
    fig = FigureEight(scenario.trajectory)
    worst, worst_k = 0.0, -1
    for k in range(80001):
        t = k * 0.002
        got, want = ex.sample(t), fig.sample(t)
        for fg, fw in zip(got, want, strict=True):
            for x, y in zip(fg, fw, strict=True):
                d = abs(x - y)
                if not d <= worst:  # also catches NaN
                    worst, worst_k = d, k
    assert worst <= 1e-9, f"max deviation {worst} at t = {worst_k * 0.002} s"


def test_hover_mission_is_one_loiter():
    """Given a hover scenario (Case II), then the mission is one loiter for the whole run at
    the hover position, and flown from there it is the Hover reference."""
    scenario = load_scenario(ROOT / "config/scenarios/case2_impulse.toml")
    (only,) = scenario_mission(scenario)
    assert only.command == M.MAV_CMD_NAV_LOITER_TIME and only.param1 == scenario.duration_s
    assert (only.x_m, only.y_m, only.z) == enu_to_ned(scenario.trajectory.position_enu_m)
    ex = started([only], p=scenario.trajectory.position_enu_m)
    hover = make_trajectory(scenario.trajectory)
    for t in (0.0, 12.3, scenario.duration_s, 1e4):
        assert ex.sample(t) == hover.sample(t)


def test_case1_events_follow_the_timeline():
    """Given Case I run at 500 Hz, then each item becomes current and is reached once, at
    its planned time, and the mission completes at 160 s."""
    ex = started(scenario_mission(load_scenario(CASE1)))
    seen: list[tuple[float, MissionEvent]] = []
    for k in range(80001):
        t = k * 0.002
        seen.extend((t, ev) for ev in ex.update(t))
    assert seen == [(0.0, MissionEvent("current", 0)),
                    (10.0, MissionEvent("reached", 0)), (10.0, MissionEvent("current", 1)),
                    (20.0, MissionEvent("reached", 1)), (20.0, MissionEvent("current", 2)),
                    (140.0, MissionEvent("reached", 2)), (140.0, MissionEvent("current", 3)),
                    (160.0, MissionEvent("reached", 3)), (160.0, MissionEvent("completed", 3))]
    assert ex.completed and ex.current_seq == 3


@pytest.mark.parametrize("start_us", [1_026_000, 1_430_000, 987_654_000, 3_600_002_000])
def test_items_end_at_their_step_from_any_start(start_us):
    """Given Case I started on the flight clock at start_us (an estimator's alignment time:
    the items' ends are float sums that round differently), then each item ends at the step
    of its planned microsecond and the mission completes at start + 160 s, not a step late."""
    ex = started(scenario_mission(load_scenario(CASE1)), t0=start_us * 1e-6)
    ends = []
    for k in range(80001):
        t_us = start_us + 2000 * k
        ends.extend(t_us - start_us for ev in ex.update(t_us * 1e-6) if ev.kind == "reached")
    assert ends == [10_000_000, 20_000_000, 140_000_000, 160_000_000]
    assert ex.completed


# ----------------------------------------------------------------------------------------
# Derivatives of every item kind against central differences
# ----------------------------------------------------------------------------------------

Q_START = q_exp((0.3, -0.5, 0.9))
P_START = (1.0, -2.0, 3.0)

KINDS = {
    "takeoff_yaw": [item(0, M.MAV_CMD_NAV_TAKEOFF, p2=6.0, p4=-120.0, z=-8.0)],
    "takeoff_keep": [item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-7.5)],
    "waypoint_yaw": [item(0, M.MAV_CMD_NAV_WAYPOINT, p1=2.0, p4=45.0, north=4.0, east=-3.0,
                          z=-6.0)],
    "waypoint_keep": [item(0, M.MAV_CMD_NAV_WAYPOINT, p1=0.0, p4=NAN, north=-6.0, east=2.0,
                           z=-1.0)],
    "loiter_travel": [item(0, M.MAV_CMD_NAV_LOITER_TIME, p1=3.0, north=2.0, east=5.0, z=-4.0)],
    "land_yaw": [item(0, M.MAV_CMD_NAV_LAND, p4=10.0)],
    "keyframe": [item(0, MAV_CMD_POSE_KEYFRAME, p1=7.0, p2=0.4, p3=-1.1, p4=2.0, north=3.0,
                      east=1.0, z=-2.5)],
    "figure": [item(0, MAV_CMD_FIGURE_EIGHT, p1=2.0, p2=30.0, p3=2.0, p4=1.0, z=-3.0)],
}


def body_rate(q0, q1, h):
    """omega = 2 Im(q* q') from two samples 2h apart (central), with sign continuity."""
    if sum(a * b for a, b in zip(q0, q1, strict=True)) < 0.0:
        q1 = tuple(-c for c in q1)
    mid = tuple(0.5 * (a + b) for a, b in zip(q0, q1, strict=True))
    dq = tuple((b - a) / (2.0 * h) for a, b in zip(q0, q1, strict=True))
    w = q_mul(q_conj(mid), dq)
    return np.array(w[1:]) * 2.0 / q_norm(mid) ** 2


def check_derivatives(ex: MissionExecutor, t: float) -> None:
    r = ex.sample(t)
    lo, hi = ex.sample(t - H), ex.sample(t + H)
    scale = 1.0 + max(map(abs, (*r.v_enu_m_s, *r.a_enu_m_s2, *r.omega_flu_rad_s,
                                *r.omega_dot_flu_rad_s2)))
    tol = 1e-6 * scale
    assert abs(q_norm(r.q_enu_flu) - 1.0) < 1e-12
    fd_v = (np.array(hi.p_enu_m) - np.array(lo.p_enu_m)) / (2 * H)
    fd_a = (np.array(hi.v_enu_m_s) - np.array(lo.v_enu_m_s)) / (2 * H)
    fd_wd = (np.array(hi.omega_flu_rad_s) - np.array(lo.omega_flu_rad_s)) / (2 * H)
    assert max_abs_diff(r.v_enu_m_s, fd_v) < tol, ("velocity", t)
    assert max_abs_diff(r.a_enu_m_s2, fd_a) < tol, ("acceleration", t)
    assert max_abs_diff(r.omega_flu_rad_s, body_rate(lo.q_enu_flu, hi.q_enu_flu, H)) < tol, \
        ("body rate", t)
    assert max_abs_diff(r.omega_dot_flu_rad_s2, fd_wd) < tol, ("body rate derivative", t)


@pytest.mark.parametrize("kind", sorted(KINDS))
@settings(max_examples=40, deadline=None)
@given(frac=st.floats(0.002, 0.998))
def test_item_derivatives_are_analytic(kind, frac):
    """Given any item kind from a tilted, displaced start, then v, a, omega and omega' equal
    central differences of p, v, q and omega inside the item, away from the instant where a
    move's travel ends and its hold begins (the jerk steps there, and a difference across it
    is off by H times that step: frac 0.48913 of loiter_travel, 13 us after it)."""
    ex = started(KINDS[kind], t0=3.0, p=P_START, q=Q_START)
    _seq, t0, t1 = ex.schedule[0]
    assert t1 > t0
    t = t0 + frac * (t1 - t0)
    seg = ex._segments[0]
    if getattr(seg, "hold", 0.0) > 0.0:
        assume(abs(t - (seg.t0 + seg.travel)) > 2 * H)
    check_derivatives(ex, t)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_items_move_and_are_continuous(kind):
    """Given any item kind, then it actually moves (position or attitude), starts from the
    start pose with zero velocity, and its reference is continuous into the hold after it."""
    ex = started(KINDS[kind], t0=3.0, p=P_START, q=Q_START)
    _seq, t0, t1 = ex.schedule[0]
    first, end = ex.sample(t0), ex.sample(t1)
    assert max_abs_diff(first.p_enu_m, P_START) < 1e-12
    assert max_abs_diff(first.q_enu_flu, Q_START) < 1e-12
    assert max_abs_diff(first.v_enu_m_s, (0, 0, 0)) < 1e-12
    mid = ex.sample(0.5 * (t0 + t1))
    moved = max(max_abs_diff(mid.p_enu_m, P_START),
                q_angle(q_mul(q_conj(mid.q_enu_flu), Q_START)))
    assert moved > 0.1
    before_end = ex.sample(t1 - 1e-7)
    assert max_abs_diff(before_end.p_enu_m, end.p_enu_m) < 1e-5
    assert q_angle(q_mul(q_conj(before_end.q_enu_flu), end.q_enu_flu)) < 1e-5
    assert max_abs_diff(end.v_enu_m_s + end.omega_flu_rad_s, (0,) * 6) == 0.0
    assert ex.sample(t1 + 50.0) == end


def test_figure_turns_about_the_world_axis():
    """Given a figure from a tilted attitude, then q_d = exp(T n) q_start with n the item's
    axis in ENU (not normalised), and the body rate is R(q_d)^T T' n."""
    ex = started(KINDS["figure"], p=P_START, q=Q_START)
    n = ned_to_enu((2.0, 1.0, -3.0))
    for t in (1.0, 7.5, 15.0, 22.0):
        r = ex.sample(t)
        x = math.pi * t / 30.0
        T, dT = math.pi * (1 - math.cos(x)), math.pi * math.pi / 30.0 * math.sin(x)
        want_q = q_mul(q_exp((T * n[0], T * n[1], T * n[2])), Q_START)
        assert q_angle(q_mul(q_conj(r.q_enu_flu), want_q)) < 1e-9
        want_w = q_rotate_inv(r.q_enu_flu, (dT * n[0], dT * n[1], dT * n[2]))
        assert max_abs_diff(r.omega_flu_rad_s, want_w) < 1e-12
        p = np.array(P_START) + 2.0 * np.array([math.sin(2 * T), math.sin(T),
                                                1 - math.cos(2 * T)])
        assert max_abs_diff(r.p_enu_m, p) < 1e-12


def test_keyframe_reaches_its_pose():
    """Given a keyframe, then it ends at its NED position and NED->FRD attitude exp(p2..p4)."""
    ex = started(KINDS["keyframe"], t0=1.0, p=P_START, q=Q_START)
    assert ex.schedule == ((0, 1.0, 8.0),)
    end = ex.sample(8.0)
    assert max_abs_diff(enu_to_ned(end.p_enu_m), (3.0, 1.0, -2.5)) < 1e-12
    want = q_exp((0.4, -1.1, 2.0))
    assert q_angle(q_mul(q_conj(q_enu_flu_to_ned_frd(end.q_enu_flu)), want)) < 1e-9


def test_takeoff_with_yaw_ends_level_at_that_heading():
    """Given a takeoff with yaw -120 deg from a tilted attitude, then it ends level at that
    NED yaw, at the target altitude above the start's x, y."""
    ex = started(KINDS["takeoff_yaw"], p=P_START, q=Q_START)
    end = ex.sample(6.0)
    assert max_abs_diff(end.p_enu_m, (1.0, -2.0, 8.0)) < 1e-12
    q_ned = q_enu_flu_to_ned_frd(end.q_enu_flu)
    half = math.radians(-120.0) / 2
    assert q_angle(q_mul(q_conj(q_ned), (math.cos(half), 0.0, 0.0, math.sin(half)))) < 1e-9
    # The ENU/FLU identity is a NED yaw of +90 deg.
    assert q_angle(level_attitude(90.0)) < 1e-12


# ----------------------------------------------------------------------------------------
# Durations from speeds, tolerances, turn time
# ----------------------------------------------------------------------------------------


def test_durations_from_speeds():
    """Given speed-timed items, then each travel lasts 1.875 distance / speed, so that the
    quintic's top speed is the speed asked (takeoff, cruise, land) and never more; the
    waypoint and loiter holds follow, and the items chain end to start."""
    limits = MissionLimits(cruise_speed_m_s=2.0, takeoff_speed_m_s=1.0, land_speed_m_s=0.5)
    items = [item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-4.0),
             item(1, M.MAV_CMD_NAV_WAYPOINT, p1=1.5, p4=NAN, north=6.0, east=8.0, z=-4.0),
             item(2, M.MAV_CMD_NAV_LOITER_TIME, p1=2.0, north=6.0, east=8.0, z=-4.0),
             item(3, M.MAV_CMD_NAV_LAND, p4=NAN)]
    ex = started(items, t0=100.0, limits=limits)
    assert ex.schedule == ((0, 100.0, 107.5), (1, 107.5, 118.375), (2, 118.375, 120.375),
                           (3, 120.375, 135.375))
    assert ex.end_time_s == 135.375
    assert max_abs_diff(ex.sample(135.375).p_enu_m, (8.0, 6.0, 0.0)) < 1e-12
    for (t0, t1), speed in (((100.0, 107.5), 1.0), ((107.5, 116.875), 2.0),
                            ((120.375, 135.375), 0.5)):
        top = max(math.dist(ex.sample(t).v_enu_m_s, (0.0, 0.0, 0.0))
                  for t in np.linspace(t0, t1, 2001))
        assert top == pytest.approx(speed, rel=1e-9)


def test_tiny_moves_are_not_made_and_yaw_takes_turn_time():
    """Given a loiter 0.5 mm from the start, then it holds the start exactly; given a yaw
    change with no distance, then it lasts 1.875 angle / turn rate, the turn rate its top
    rate (no attitude step)."""
    ex = started([item(0, M.MAV_CMD_NAV_LOITER_TIME, p1=4.0, north=0.0005, z=0.0)])
    assert ex.schedule == ((0, 0.0, 4.0),)
    assert ex.sample(1.0).p_enu_m == (0.0, 0.0, 0.0)
    limits = MissionLimits(turn_rate_deg_s=45.0)
    ex = started([item(0, M.MAV_CMD_NAV_WAYPOINT, p4=0.0)], limits=limits)  # yaw 90 -> 0
    assert ex.schedule[0][2] == pytest.approx(3.75, abs=1e-12)
    top = max(math.dist(ex.sample(t).omega_flu_rad_s, (0.0, 0.0, 0.0))
              for t in np.linspace(0.0, 3.75, 2001))
    assert top == pytest.approx(math.radians(45.0), rel=1e-9)
    check_derivatives(ex, 0.7)


# ----------------------------------------------------------------------------------------
# Events, completion, set_current
# ----------------------------------------------------------------------------------------

THREE = [item(0, M.MAV_CMD_NAV_LOITER_TIME, p1=1.0),
         item(1, M.MAV_CMD_NAV_LOITER_TIME, p1=0.0),  # zero length
         item(2, M.MAV_CMD_NAV_WAYPOINT, p1=0.0, p4=NAN, north=2.0)]


def test_events_once_each_in_order():
    """Given updates that jump over items, then every current/reached event still comes
    once, in order, a zero-length item included, then 'completed' once."""
    ex = started(THREE, t0=10.0)
    assert ex.update(9.0) == [] and ex.current_seq == 0 and not ex.completed
    assert ex.update(10.0) == [MissionEvent("current", 0)]
    assert ex.update(10.5) == []
    assert ex.update(11.0) == [MissionEvent("reached", 0), MissionEvent("current", 1),
                               MissionEvent("reached", 1), MissionEvent("current", 2)]
    assert ex.current_seq == 2
    assert ex.update(11.5) == []
    assert ex.update(100.0) == [MissionEvent("reached", 2), MissionEvent("completed", 2)]
    assert ex.update(200.0) == [] and ex.completed
    final = ex.sample(1e6)
    assert final.p_enu_m == pytest.approx((0.0, 2.0, 0.0))
    assert final.v_enu_m_s == (0.0, 0.0, 0.0)
    assert ex.sample(0.0).p_enu_m == (0.0, 0.0, 0.0)  # before the start: the start pose


def test_set_current_replans_from_the_given_pose():
    """Given set_current(2) mid-mission, then item 2 starts at that time from the given pose,
    events restart there, and items before it are skipped."""
    ex = started(THREE)
    ex.update(0.5)
    ex.set_current(2, 5.0, (0.0, 1.0, 0.0), level_attitude(0.0))
    assert not ex.completed and ex.current_seq == 2
    assert ex.schedule == ((2, 5.0, 5.9375),)  # 1 m at up to 2 m/s
    assert ex.update(5.0) == [MissionEvent("current", 2)]
    r = ex.sample(5.0)
    assert r.p_enu_m == (0.0, 1.0, 0.0) and r.q_enu_flu == level_attitude(0.0)
    assert ex.sample(5.9375).p_enu_m == pytest.approx((0.0, 2.0, 0.0))
    assert ex.update(6.0) == [MissionEvent("reached", 2), MissionEvent("completed", 2)]
    with pytest.raises(ValueError, match="no mission item 3"):
        ex.set_current(3, 0.0, (0, 0, 0), (1, 0, 0, 0))


def test_executor_refuses_what_cannot_be_flown():
    """Given an empty mission or an unsupported item, then the executor refuses it; an
    unstarted executor refuses to sample; a mission beyond the geofence still flies."""
    with pytest.raises(ValueError, match="empty"):
        MissionExecutor([], LIMITS)
    with pytest.raises(ValueError, match="not executable"):
        MissionExecutor([item(0, M.MAV_CMD_DO_SET_SERVO)], LIMITS)
    with pytest.raises(RuntimeError, match="not started"):
        MissionExecutor(THREE, LIMITS).sample(0.0)
    far = [item(0, M.MAV_CMD_NAV_WAYPOINT, p4=NAN, north=50.0)]
    started(far, limits=MissionLimits(max_distance_m=10.0))
    with pytest.raises(ValueError, match="cruise_speed_m_s"):
        MissionLimits(cruise_speed_m_s=0.0)


# ----------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------

WP = M.MAV_CMD_NAV_WAYPOINT
BAD = [
    ("unsupported command", item(0, M.MAV_CMD_DO_SET_SERVO), M.MAV_MISSION_UNSUPPORTED),
    ("global frame", item(0, WP, p4=NAN, frame=M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT),
     M.MAV_MISSION_UNSUPPORTED_FRAME),
    ("negative hold", item(0, WP, p1=-1.0, p4=NAN), M.MAV_MISSION_INVALID_PARAM1),
    ("NaN loiter time", item(0, M.MAV_CMD_NAV_LOITER_TIME, p1=NAN),
     M.MAV_MISSION_INVALID_PARAM1),
    ("keyframe time 0", item(0, MAV_CMD_POSE_KEYFRAME, p1=0.0), M.MAV_MISSION_INVALID_PARAM1),
    ("figure amplitude inf", item(0, MAV_CMD_FIGURE_EIGHT, p1=math.inf, p2=1.0, p3=1.0),
     M.MAV_MISSION_INVALID_PARAM1),
    ("negative climb time", item(0, M.MAV_CMD_NAV_TAKEOFF, p2=-1.0, p4=NAN, z=-1.0),
     M.MAV_MISSION_INVALID_PARAM2),
    ("figure duration 0", item(0, MAV_CMD_FIGURE_EIGHT, p1=1.0, p2=0.0, p3=1.0),
     M.MAV_MISSION_INVALID_PARAM2),
    ("keyframe NaN attitude", item(0, MAV_CMD_POSE_KEYFRAME, p1=1.0, p2=NAN),
     M.MAV_MISSION_INVALID_PARAM2),
    ("figure without axis", item(0, MAV_CMD_FIGURE_EIGHT, p1=1.0, p2=1.0),
     M.MAV_MISSION_INVALID_PARAM3),
    ("figure NaN axis", item(0, MAV_CMD_FIGURE_EIGHT, p1=1.0, p2=1.0, p3=NAN, z=1.0),
     M.MAV_MISSION_INVALID_PARAM3),
    ("infinite yaw", item(0, WP, p4=math.inf), M.MAV_MISSION_INVALID_PARAM4),
    ("land infinite yaw", item(0, M.MAV_CMD_NAV_LAND, p4=-math.inf),
     M.MAV_MISSION_INVALID_PARAM4),
    ("x beyond int32", item(0, WP, p4=NAN)._replace(x=2 ** 31), M.MAV_MISSION_INVALID_PARAM5_X),
    ("y beyond int32", item(0, M.MAV_CMD_NAV_LAND, p4=NAN)._replace(y=-(2 ** 31) - 1),
     M.MAV_MISSION_INVALID_PARAM6_Y),
    ("NaN altitude", item(0, WP, p4=NAN, z=NAN), M.MAV_MISSION_INVALID_PARAM7),
    ("takeoff to inf", item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-math.inf),
     M.MAV_MISSION_INVALID_PARAM7),
    ("waypoint outside the fence", item(0, WP, p4=NAN, north=800.0, east=700.0),
     M.MAV_MISSION_DENIED),
    ("takeoff above the fence", item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-1001.0),
     M.MAV_MISSION_DENIED),
    ("keyframe outside the fence", item(0, MAV_CMD_POSE_KEYFRAME, p1=1.0, z=2000.0),
     M.MAV_MISSION_DENIED),
]


@pytest.mark.parametrize(("what", "bad", "result"), BAD, ids=[b[0] for b in BAD])
def test_validation_names_the_slot(what, bad, result):
    """Given a valid mission with one bad item at seq 2, then validation returns that
    item's MAV_MISSION_RESULT and seq 2."""
    good = [item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-5.0),
            item(1, WP, p1=1.0, p4=30.0, north=3.0, z=-5.0)]
    items = [*good, bad.with_seq(2), item(3, M.MAV_CMD_NAV_LAND, p4=NAN)]
    assert validate_mission(items, LIMITS) == (result, 2), what
    check = check_mission(items, LIMITS)
    assert type(check.result) is MAV_MISSION_RESULT, "a MAV_MISSION_RESULT member, not an int"
    assert refusal(check) == f"{check.result.name}: {check.reason}"
    assert check.reason.startswith("item 2: ") and check.reason.count("item 2") == 1, \
        check.reason


def test_validation_sequence_count_and_fence():
    """Given seq gaps, too many items, or a figure whose extent A sqrt 5 leaves the fence
    from where it starts, then the matching result; NaN yaws and ignored slots pass."""
    ok = [item(0, M.MAV_CMD_NAV_LOITER_TIME, p1=1.0), item(1, M.MAV_CMD_NAV_LAND, p4=NAN)]
    assert validate_mission(ok, LIMITS) == (M.MAV_MISSION_ACCEPTED, None)
    assert validate_mission([ok[0], ok[1].with_seq(2)], LIMITS) == (
        M.MAV_MISSION_INVALID_SEQUENCE, 2)
    assert validate_mission([ok[1], ok[0]], LIMITS) == (M.MAV_MISSION_INVALID_SEQUENCE, 1)
    assert validate_mission(ok, MissionLimits(max_items=1)) == (M.MAV_MISSION_NO_SPACE, None)
    assert validate_mission([], LIMITS) == (M.MAV_MISSION_ACCEPTED, None)
    # Ignored slots: takeoff x, y and p1/p3; waypoint p2/p3; land x, y, z; figure x, y.
    ignored = [item(0, M.MAV_CMD_NAV_TAKEOFF, p1=NAN, p3=NAN, p4=NAN, north=1e5, z=-5.0),
               item(1, WP, p2=NAN, p3=math.inf, p4=NAN, z=-5.0),
               item(2, M.MAV_CMD_NAV_LAND, p4=NAN, z=NAN, north=1e5)]
    assert validate_mission(ignored, LIMITS) == (M.MAV_MISSION_ACCEPTED, None)
    limits = MissionLimits(max_distance_m=30.0)
    start = item(0, WP, p4=NAN, north=10.0, z=-10.0)  # |start| = 14.14 m
    fits = item(1, MAV_CMD_FIGURE_EIGHT, p1=7.0, p2=10.0, p3=1.0)  # 14.14 + 15.65 < 30
    too_big = fits._replace(param1=7.2)  # 14.14 + 16.10 > 30
    assert validate_mission([start, fits], limits) == (M.MAV_MISSION_ACCEPTED, None)
    assert validate_mission([start, too_big], limits) == (M.MAV_MISSION_DENIED, 1)


def test_validation_tables_cover_every_command_and_the_first_failure_wins():
    """Given the supported commands, then each has its parameter rules and its motion; given
    an item failing several checks, then the earliest one (command, frame, x, y, parameters
    in slot order, then the figure's axis) is the result."""
    commands = mission_mod.SUPPORTED_COMMANDS
    assert set(validation._PARAM_RULES) == set(validation._MOTIONS) == commands
    bad_all = dict(p1=-1.0, p2=-1.0, p3=NAN, p4=math.inf, z=NAN)
    first = [(item(0, 17, **bad_all), M.MAV_MISSION_UNSUPPORTED),
             (item(0, WP, frame=M.MAV_FRAME_BODY_NED, **bad_all),
              M.MAV_MISSION_UNSUPPORTED_FRAME),
             (item(0, WP, **bad_all)._replace(x=2 ** 31, y=2 ** 31),
              M.MAV_MISSION_INVALID_PARAM5_X),
             (item(0, M.MAV_CMD_NAV_TAKEOFF, **bad_all), M.MAV_MISSION_INVALID_PARAM2),
             (item(0, MAV_CMD_POSE_KEYFRAME, p1=1.0, p2=NAN, p4=NAN),
              M.MAV_MISSION_INVALID_PARAM2),
             (item(0, MAV_CMD_FIGURE_EIGHT, p1=1.0, p2=1.0, p4=NAN),
              M.MAV_MISSION_INVALID_PARAM4)]
    for bad, result in first:
        assert validate_mission([bad], LIMITS) == (result, 0), bad


def test_yaw_conversion_round_trip():
    """Given level_attitude(yaw), then its NED->FRD quaternion is the yaw about NED down."""
    for yaw in (-170.0, -45.0, 0.0, 33.0, 180.0):
        half = math.radians(yaw) / 2
        want = (math.cos(half), 0.0, 0.0, math.sin(half))
        got = q_enu_flu_to_ned_frd(level_attitude(yaw))
        assert q_angle(q_mul(q_conj(got), want)) < 1e-12
        assert q_angle(q_mul(q_conj(q_ned_frd_to_enu_flu(want)), level_attitude(yaw))) < 1e-12


# ----------------------------------------------------------------------------------------
# Breakpoints: the sample at a boundary is the next segment's (right-hand limit)
# ----------------------------------------------------------------------------------------

BOUNDARIES = [item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-4.0),
              item(1, MAV_CMD_POSE_KEYFRAME, p1=6.0, p2=0.2, p3=-0.3, p4=1.2, north=2.0,
                   east=1.0, z=-5.0),
              item(2, MAV_CMD_FIGURE_EIGHT, p1=1.0, p2=20.0, p3=2.0, p4=1.0, z=-3.0),
              item(3, M.MAV_CMD_NAV_WAYPOINT, p1=0.0, p4=30.0, north=-1.0, east=3.0, z=-4.0),
              item(4, M.MAV_CMD_NAV_LOITER_TIME, p1=2.0, north=-1.0, east=3.0, z=-4.0),
              item(5, M.MAV_CMD_NAV_LAND, p4=NAN)]


def fields(ref) -> np.ndarray:
    return np.concatenate([np.asarray(f, float) for f in ref])


def test_segment_boundaries_take_the_next_segment():
    """Given a mission of every kind, when sampled at exactly each planned boundary (start,
    item ends, figure start and end), then every field equals the sample 1 ns later: the
    next item at tau = 0, never the previous item's end."""
    ex = started(BOUNDARIES, t0=2.0, p=P_START, q=Q_START)
    times = sorted({t for _seq, t0, t1 in ex.schedule for t in (t0, t1)})
    assert len(times) == 7
    for t in times:
        assert max_abs_diff(fields(ex.sample(t)), fields(ex.sample(t + 1e-9))) < 1e-6, t
    # At the figure's start the feed-forward is there at once (T'' = pi k^2, not 0), where
    # the keyframe before it had come to rest.
    _seq, t_fig, _end = ex.schedule[2]
    at, before = ex.sample(t_fig), ex.sample(t_fig - 1e-9)
    assert norm(at.omega_dot_flu_rad_s2) > 0.05 and norm(before.omega_dot_flu_rad_s2) < 1e-6
    assert norm(at.a_enu_m_s2) > 0.05 and norm(before.a_enu_m_s2) < 1e-6


def norm(v) -> float:
    return float(np.linalg.norm(np.asarray(v, float)))


def test_case1_mission_figure_start_has_the_feed_forward():
    """Given the Case I mission, then at exactly t = 20 s its reference is the figure's
    right-hand limit, as the trajectory's is."""
    scenario = load_scenario(CASE1)
    ex = started(scenario_mission(scenario))
    got, want = ex.sample(20.0), FigureEight(scenario.trajectory).sample(20.0)
    assert max_abs_diff(fields(got), fields(want)) < 1e-12
    k = math.pi / 120.0
    assert max_abs_diff(got.omega_dot_flu_rad_s2, math.pi * k * k * np.array([1, 2, 3])) < 1e-15


def test_a_moves_end_into_its_hold_is_continuous_in_velocity_and_acceleration():
    """Where a loiter's travel ends and its hold begins, velocity and acceleration are
    zero on both sides (the quintic's ends): only the jerk steps there."""
    ex = started(KINDS["loiter_travel"], t0=3.0, p=P_START, q=Q_START)
    seg = ex._segments[0]
    end = seg.t0 + seg.travel
    before, after = ex.sample(end - 1e-7), ex.sample(end + 1e-7)
    assert seg.hold > 0.0 and max_abs_diff(after.v_enu_m_s, (0, 0, 0)) == 0.0
    assert max_abs_diff(before.v_enu_m_s, (0, 0, 0)) < 1e-9
    assert max_abs_diff(before.a_enu_m_s2, after.a_enu_m_s2) < 1e-4
