"""Missions the vehicle can fly (fcu/envelope/feasibility.py, fcu/mission/): nominal wrench, rotor
speed envelope, time scaling, stretching of speed-timed items, refusal of user-timed ones."""

from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.config.scenario import Gains, load_scenario, load_vehicle
from common.wire.mavlink import MAV, MAV_CMD_FIGURE_EIGHT, MAV_CMD_POSE_KEYFRAME
from common.wire.mission_items import MissionItem, local_xy
from fcu.control.allocation import Allocator
from fcu.control.dualquat import q_exp, q_rotate_inv
from fcu.control.tracker import DualQuaternionTracker
from fcu.envelope.excess import KINDS, excess_kernel
from fcu.envelope.feasibility import MARGIN, Envelope, envelope, nominal_wrench
from fcu.mission.executor import MissionExecutor
from fcu.mission.limits import MissionLimits
from fcu.mission.segments import Figure as _Figure
from fcu.mission.segments import Move as _Move
from fcu.mission.validation import MissionCheck, check_mission, validate_mission
from fcu.stages import Reference, VehicleState
from gcs.run.scenario_mission import scenario_mission

M = MAV
ROOT = Path(__file__).resolve().parents[2]
TILTED = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
PLANAR = load_vehicle(ROOT / "config/vehicles/hexa_planar.toml")
CASE1 = ROOT / "config/scenarios/case1_figure8.toml"
NAN = math.nan
ZERO = (0.0, 0.0, 0.0)


def item(seq: int, command: int, p1: float = 0.0, p2: float = 0.0, p3: float = 0.0,
         p4: float = 0.0, north: float = 0.0, east: float = 0.0, z: float = 0.0) -> MissionItem:
    return MissionItem(seq, M.MAV_FRAME_LOCAL_NED, command, int(seq == 0), 1, p1, p2, p3, p4,
                       local_xy(north), local_xy(east), z)


def started(items, limits: MissionLimits) -> MissionExecutor:
    ex = MissionExecutor(items, limits)
    ex.start(0.0, ZERO, (1.0, 0.0, 0.0, 0.0))
    return ex


def dense_peak(env: Envelope, ex: MissionExecutor, t0: float, t1: float,
               dt: float = 1e-3) -> float:
    """Highest rotor speed of the nominal wrench along the executor's reference."""
    return max(env.peak(ex.sample(t)).speed_rad_s for t in np.arange(t0, t1 + dt, dt))


def dense_tilt_rate(env: Envelope, ex: MissionExecutor, t0: float, t1: float,
                    dt: float = 1e-3) -> float:
    """Fastest tilt of the nominal wrench's allocation along the executor's reference, by
    differences of atan2 (wrapped) every dt: independent of the envelope's formula."""
    om = np.vstack([env.omega_sq(ex.sample(t)) for t in np.arange(t0, t1 + dt, dt)])
    tilt = np.arctan2(om[:, 0::2], om[:, 1::2])
    step = np.angle(np.exp(1j * np.diff(tilt, axis=0)))
    return float(np.abs(step).max() / dt)


# ----------------------------------------------------------------------------------------
# The nominal wrench and its allocation
# ----------------------------------------------------------------------------------------


def test_nominal_wrench_in_hover_is_the_weight():
    """Given hover at identity, then f_b = [0, 0, m g], tau_b = 0; tilted, f_b = m g R^T e_z."""
    rest = Reference((1.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), ZERO, ZERO, ZERO, ZERO)
    force, torque = nominal_wrench(TILTED, rest)
    assert force == pytest.approx((0.0, 0.0, 4.27 * 9.81), abs=1e-12)
    assert torque == ZERO
    q = q_exp((0.4, -0.2, 1.0))
    force, _ = nominal_wrench(TILTED, rest._replace(q_enu_flu=q))
    assert force == pytest.approx(q_rotate_inv(q, (0.0, 0.0, 4.27 * 9.81)), abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.tuples(*[st.floats(-3.0, 3.0)] * 18))
def test_nominal_wrench_is_the_trackers_at_zero_error(x):
    """Given any reference, when the tracker sees a state exactly on it, then its wrench is
    the nominal wrench (the feed-forward the check budgets for)."""
    q = q_exp(x[0:3])
    ref = Reference(x[3:6], q, x[6:9], x[9:12], x[12:15], x[15:18])
    gains = Gains(*([(2.0, 2.0, 2.0)] * 2), *([(0.0, 0.0, 0.0)] * 2), *([(5.0, 5.0, 5.0)] * 2))
    state = VehicleState(ref.p_enu_m, q, q_rotate_inv(q, ref.v_enu_m_s), ref.omega_flu_rad_s)
    out = DualQuaternionTracker(TILTED, gains).update(state, ref, 0.002)
    force, torque = nominal_wrench(TILTED, ref)
    assert np.allclose(out.force_flu_n, force, atol=1e-9)
    assert np.allclose(out.torque_flu_nm, torque, atol=1e-9)


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_envelope_speeds_are_the_allocators(vehicle):
    """Given a reference, then the envelope's rotor speeds are those the flight allocation
    (fcu.control.allocation.Allocator) gives for the nominal wrench, and the limit is 85 % of
    w_max."""
    env = Envelope(vehicle)
    assert env.limit == MARGIN * 1700.0 == pytest.approx(1445.0)
    ref = Reference(ZERO, q_exp((0.3, 0.1, -0.7)), (1.0, 0.0, 0.0), (2.0, -1.0, 3.0),
                    (0.5, -0.2, 0.9), (1.0, 2.0, -1.5))
    want = Allocator(vehicle).allocate(*nominal_wrench(vehicle, ref)).speed_rad_s
    assert np.allclose(env.speeds(ref)[0], want, rtol=1e-12)
    assert env.peak(ref).speed_rad_s == pytest.approx(max(want), rel=1e-12)


# ----------------------------------------------------------------------------------------
# Time scaling: Omega(D) = Omega_0 + Omega_1 / D^2
# ----------------------------------------------------------------------------------------

Q0 = q_exp((0.3, -0.5, 0.9))
SEGMENTS = {
    "move": _Move(0, 0.0, (1.0, -2.0, 3.0), (2.0, -1.0, 0.5), Q0, (0.4, -0.3, 0.8), 1.0, 0.0),
    "move_no_turn": _Move(0, 0.0, (1.0, -2.0, 3.0), (-3.0, 0.0, 1.0), Q0, None, 1.0, 0.0),
    "figure": _Figure(0, 0.0, (1.0, -2.0, 3.0), Q0, 2.0, 1.0, (2.0, -1.0, 3.0)),
}


@pytest.mark.parametrize("kind", sorted(SEGMENTS))
@pytest.mark.parametrize("duration", [0.7, 3.0, 40.0])
def test_time_scaling_matches_the_flown_reference(kind, duration):
    """Given a segment's path, when the envelope predicts its rotor speeds for a duration D
    from the 1 s path, then they equal those of the segment planned with D and sampled
    through its own `sample` (so the scaling law holds for moves, turns and figures)."""
    env = envelope(TILTED)
    unit = SEGMENTS[kind]
    scaling = env.scaling(unit)
    seg = (unit.retimed(duration) if isinstance(unit, _Move) else
           _Figure(0, 0.0, unit.figure.p0, unit.figure.q0, unit.figure.amp, duration,
                   unit.figure.n))
    sigma = unit.instants()
    flown = np.array([env.speeds(seg.sample(float(s) * duration))[0] for s in sigma
                      if s < 1.0])
    assert np.allclose(scaling.speeds(duration)[sigma < 1.0], flown, rtol=1e-9)


@pytest.mark.parametrize("kind", sorted(SEGMENTS))
@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_shortest_duration_is_the_bound(kind, vehicle):
    """Given a segment, then at the shortest duration and any longer one the sampled peak is
    within the limit, and 0.1 % faster it is not."""
    scaling = envelope(vehicle).scaling(SEGMENTS[kind])
    shortest = scaling.shortest()
    assert 0.1 < shortest < 200.0
    for factor in (1.0, 1.001, 1.5, 10.0, 1e6):
        assert scaling.fits(shortest * factor), factor
    assert not scaling.fits(shortest * 0.999)


@pytest.mark.parametrize("kind", sorted(SEGMENTS))
def test_samples_catch_the_peak(kind):
    """Given a segment flown near its limit, then the peak over the check instants is within
    0.2 % of the peak over 20001 evenly spaced instants."""
    env = envelope(TILTED)
    seg = SEGMENTS[kind]
    scaling = env.scaling(seg)
    duration = scaling.shortest()
    sparse = scaling.peak(duration).speed_rad_s
    unit = seg.path(np.linspace(0.0, 1.0, 20001))
    u = 1.0 / duration ** 2
    om0 = env.omega_sq(unit._replace(v_enu_m_s=ZERO, a_enu_m_s2=ZERO, omega_flu_rad_s=ZERO,
                                     omega_dot_flu_rad_s2=ZERO))
    om = om0 + u * (env.omega_sq(unit) - om0)
    dense = float(np.max(np.sqrt(np.hypot(om[:, 0::2], om[:, 1::2]))))
    assert sparse <= dense * (1.0 + 1e-5)  # its instants may sit nearer the peak
    assert sparse >= dense * 0.998


# ----------------------------------------------------------------------------------------
# Speed-timed items are stretched
# ----------------------------------------------------------------------------------------

LEGS = [item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-3.0),
        *(item(i, M.MAV_CMD_NAV_WAYPOINT, p4=NAN, north=2.0 * i, z=-3.0) for i in range(1, 5)),
        item(5, M.MAV_CMD_NAV_LAND, p4=NAN)]


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_short_fast_legs_are_stretched(vehicle):
    """Given 2 m waypoint legs at 3.75 m/s (1 s each, a quintic's top speed 1.875 times its
    mean: 11.5 m/s^2 peak), then without the vehicle each leg is planned in 1 s and needs
    more than the margin; with it the mission is
    accepted, every leg is planned longer than 1 s and the reference flown (sampled every
    1 ms) stays within the margin."""
    env = envelope(vehicle)
    plain = started(LEGS, MissionLimits(cruise_speed_m_s=3.75))
    assert [round(t1 - t0, 12) for _s, t0, t1 in plain.schedule[1:5]] == [1.0] * 4
    assert dense_peak(env, plain, *plain.schedule[2][1:]) > env.limit

    limits = MissionLimits(cruise_speed_m_s=3.75, vehicle=vehicle)
    assert check_mission(LEGS, limits) == MissionCheck(M.MAV_MISSION_ACCEPTED, None, "")
    ex = started(LEGS, limits)
    legs = [t1 - t0 for _s, t0, t1 in ex.schedule[1:5]]
    assert all(1.02 < leg < 2.5 for leg in legs), legs
    assert legs[1] == pytest.approx(legs[2], rel=1e-9) == legs[3]  # the same leg, at rest
    assert dense_peak(env, ex, 0.0, ex.end_time_s) <= env.limit
    # The tilt servos bound these legs (the rotors alone would allow ~1.05 s) ...
    assert dense_tilt_rate(env, plain, *plain.schedule[2][1:]) > 3.0 * env.tilt_limit
    # ... and the stretched legs keep them within TILT_MARGIN of their rate (to sampling).
    t0, t1 = ex.schedule[2][1:]
    assert env.tilt_limit * 0.97 < dense_tilt_rate(env, ex, t0, t1) <= env.tilt_limit * 1.001
    # Stretching keeps the geometry: the same end poses, only later.
    assert ex.sample(ex.end_time_s).p_enu_m == pytest.approx(plain.sample(1e3).p_enu_m)


def test_stretch_only_lengthens():
    """Given slow items (the speed already fits), then their timeline is unchanged."""
    slow = [item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-3.0),
            item(1, M.MAV_CMD_NAV_WAYPOINT, p1=1.0, p4=45.0, north=10.0, east=-4.0, z=-3.0),
            item(2, M.MAV_CMD_NAV_LAND, p4=NAN)]
    assert started(slow, MissionLimits(vehicle=TILTED)).schedule == \
        started(slow, MissionLimits()).schedule


def test_executor_replans_with_the_same_rule():
    """Given set_current to a short fast leg from a pose other than the planned one, then
    the executor stretches it there too."""
    limits = MissionLimits(vehicle=TILTED)
    ex = started(LEGS, limits)
    ex.set_current(3, 50.0, (0.0, 5.0, 3.0), (1.0, 0.0, 0.0, 0.0))  # 1 m to go: 0.5 s
    (_seq, t0, t1), *_rest = ex.schedule
    assert t0 == 50.0 and 0.6 < t1 - t0 < 2.0
    assert dense_peak(envelope(TILTED), ex, t0, t1) <= envelope(TILTED).limit
    assert dense_tilt_rate(envelope(TILTED), ex, t0, t1) <= envelope(TILTED).tilt_limit * 1.001


# ----------------------------------------------------------------------------------------
# User-timed items are refused, with the reason
# ----------------------------------------------------------------------------------------

START = [item(0, M.MAV_CMD_NAV_TAKEOFF, p4=NAN, z=-3.0)]


def test_fast_keyframe_is_refused_with_the_reason():
    """Given a keyframe of 2 m in 0.5 s, then the mission is refused (DENIED) at that item,
    with a reason naming the item, the rotor speed, the limit and the slot to lengthen; the
    duration it proposes is accepted."""
    fast = item(1, MAV_CMD_POSE_KEYFRAME, p1=0.5, north=2.0, z=-3.0)
    limits = MissionLimits(vehicle=TILTED)
    result, seq, reason = check_mission([*START, fast], limits)
    assert (result, seq) == (M.MAV_MISSION_DENIED, 1)
    assert validate_mission([*START, fast], limits) == (M.MAV_MISSION_DENIED, 1)
    assert reason.startswith("item 1: tilt servo ") and " rad/s, limit 3.0 (75% of 4.0): " \
        in reason
    needed = float(reason.split("needs ")[1].split(" rad/s")[0])
    assert needed > 3.0
    assert reason.endswith(" s") and "lengthen p1 to " in reason
    proposed = float(reason.split("lengthen p1 to ")[1][:-2])
    assert 0.5 < proposed < 2.0
    assert check_mission([*START, fast._replace(param1=proposed)], limits).result == \
        M.MAV_MISSION_ACCEPTED
    assert check_mission([*START, fast], MissionLimits()).result == M.MAV_MISSION_ACCEPTED


@pytest.mark.parametrize(("bad", "slot"), [
    (item(1, M.MAV_CMD_NAV_TAKEOFF, p2=0.8, p4=NAN, z=-8.0), "p2"),
    (item(1, MAV_CMD_FIGURE_EIGHT, p1=3.0, p2=4.0, p3=2.0, p4=1.0, z=-3.0), "p2"),
    (item(1, MAV_CMD_POSE_KEYFRAME, p1=0.4, p2=1.5, p3=0.0, p4=0.0, z=-3.0), "p1"),
], ids=["takeoff", "figure", "keyframe_turn"])
def test_user_timed_items_are_refused(bad, slot):
    """Given a timed takeoff, a figure or a pure turn that is too fast, then DENIED at that
    item with the slot that holds its duration."""
    result, seq, reason = check_mission([*START, bad], MissionLimits(vehicle=TILTED))
    assert (result, seq) == (M.MAV_MISSION_DENIED, 1), reason
    assert f"lengthen {slot} to " in reason


def test_attitude_that_cannot_be_held_is_refused():
    """Given a heavier planar vehicle (hover at identity fits, at 90 deg of roll it does not)
    and a slow keyframe to that roll, then DENIED: no duration helps."""
    heavy = dataclasses.replace(PLANAR, mass_kg=6.0)
    roll = item(1, MAV_CMD_POSE_KEYFRAME, p1=20.0, p2=math.pi / 2, z=-3.0)
    result, seq, reason = check_mission([*START, roll], MissionLimits(vehicle=heavy))
    assert (result, seq) == (M.MAV_MISSION_DENIED, 1)
    assert reason.endswith(": attitude too demanding at any speed"), reason
    level = roll._replace(param2=0.0, param4=math.pi / 2)  # a yaw: fine
    assert check_mission([*START, level], MissionLimits(vehicle=heavy)).result == \
        M.MAV_MISSION_ACCEPTED


def test_items_are_checked_in_order():
    """Given a too-fast keyframe before an item with a bad parameter, then the keyframe is
    reported (the first failing item)."""
    items = [*START, item(1, MAV_CMD_POSE_KEYFRAME, p1=0.5, north=2.0, z=-3.0),
             item(2, M.MAV_CMD_NAV_WAYPOINT, p1=-1.0, p4=NAN)]
    assert check_mission(items, MissionLimits(vehicle=TILTED))[:2] == (M.MAV_MISSION_DENIED, 1)
    assert check_mission(items, MissionLimits())[:2] == (M.MAV_MISSION_INVALID_PARAM1, 2)


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_case1_is_accepted_unchanged(vehicle):
    """Given Case I's mission, then it is accepted, nothing is stretched (0-10-20-140-160 s
    exactly) and its reference stays within the margin."""
    items = scenario_mission(load_scenario(CASE1))
    limits = MissionLimits(vehicle=vehicle)
    assert check_mission(items, limits) == MissionCheck(M.MAV_MISSION_ACCEPTED, None, "")
    ex = started(items, limits)
    assert ex.schedule == ((0, 0.0, 10.0), (1, 10.0, 20.0), (2, 20.0, 140.0),
                           (3, 140.0, 160.0))
    assert dense_peak(envelope(vehicle), ex, 0.0, 160.0, dt=0.05) <= envelope(vehicle).limit


def test_geofence_refusal_has_a_reason():
    """Given a waypoint beyond the geofence, then DENIED with the distance and the fence."""
    far = item(1, M.MAV_CMD_NAV_WAYPOINT, p4=NAN, north=40.0, east=30.0, z=-3.0)
    check = check_mission([*START, far], MissionLimits(max_distance_m=30.0))
    assert check == (M.MAV_MISSION_DENIED, 1, "item 1: beyond the geofence (50 m > 30 m)")


def test_five_hundred_items_are_checked():
    """Given 500 items (fast legs to stretch, keyframes, figures), then validation accepts
    them and the executor plans them."""
    rng = np.random.default_rng(7)
    items = [*START]
    for i in range(1, 499):
        n, e = (float(v) for v in rng.uniform(-20.0, 20.0, 2))
        items.append([item(i, M.MAV_CMD_NAV_WAYPOINT, p4=NAN, north=n, east=e, z=-5.0),
                      item(i, MAV_CMD_POSE_KEYFRAME, p1=20.0, p2=0.3, p3=-0.2, p4=0.5,
                           north=n, east=e, z=-5.0),
                      item(i, MAV_CMD_FIGURE_EIGHT, p1=2.0, p2=60.0, p3=2.0, p4=1.0,
                           z=-3.0)][i % 3])
    items.append(item(499, M.MAV_CMD_NAV_LAND, p4=NAN))
    limits = MissionLimits(vehicle=TILTED)
    assert check_mission(items, limits).result == M.MAV_MISSION_ACCEPTED
    assert started(items, limits).end_time_s > 0.0  # how long: benchmarks/mission_envelope.py


def test_feasibility_is_pure():
    """fcu/envelope/feasibility.py imports neither MAVLink nor I/O nor clocks."""
    tree = ast.parse((ROOT / "fcu/envelope/feasibility.py").read_text())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    io = {"pymavlink", "zenoh", "time", "socket", "threading", "select", "common.wire.mavlink",
          "common.links", "common.wire.simlink", "fcu.mission", "fcu.edge.mission_protocol"}
    assert names and not {m for m in names if m in io or m.split(".")[0] in io}


# ----------------------------------------------------------------------------------------
# Tilt servos: rates along the path and steps at its ends
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
@pytest.mark.parametrize("duration", [6.0, 20.0])
def test_tilt_step_at_a_figure_start_is_the_flown_one(vehicle, duration):
    """Given a figure-infinity (T'' = pi k^2 at once), then the tilt step the envelope finds at
    its start is the one between the allocation of the figure's first sample and of the
    same pose at rest, by atan2 of the flown reference."""
    env = envelope(vehicle)
    seg = _Figure(0, 0.0, (0.0, 0.0, 3.0), (1.0, 0.0, 0.0, 0.0), 1.5, duration,
                  (0.5, -0.3, 1.0))
    sc = env.scaling(seg)
    # Only the step can count: every other limit is infinite, the step's is 1 rad.
    step, kind, _rotor, sample, need, limit = excess_kernel(
        sc.om0, sc.om1, sc.dom0, sc.dom1, sc.is_end, duration, math.inf, 0.0, 0.0, math.inf,
        1.0)
    first = env.omega_sq(seg.sample(0.0))[0]
    rest = env.omega_sq(seg.sample(0.0)._replace(
        v_enu_m_s=ZERO, a_enu_m_s2=ZERO, omega_flu_rad_s=ZERO, omega_dot_flu_rad_s2=ZERO))[0]
    d = np.arctan2(first[0::2], first[1::2]) - np.arctan2(rest[0::2], rest[1::2])
    want = np.abs(np.angle(np.exp(1j * d)))
    assert want.max() > 1e-3  # the figure does start with a step
    assert KINDS[kind] == "tilt step" and limit == 1.0 and sc.is_end[sample]
    assert step == need and need >= want.max() * (1 - 1e-6)  # the start's, or a larger end
    if sample == 0:
        assert need == pytest.approx(want.max(), rel=1e-6)


@pytest.mark.parametrize("vehicle", [TILTED, PLANAR], ids=["tilted", "planar"])
def test_fast_figure_is_refused_naming_a_tilt_servo(vehicle):
    """Given a 2 m figure-infinity in 5 s (rotor speeds fit on the tilted preset), then DENIED
    naming a tilt servo and its limit; the duration it proposes is accepted and its tilt rates
    (dense, by differences) stay within the limit."""
    fig = item(1, MAV_CMD_FIGURE_EIGHT, p1=2.0, p2=5.0, z=-3.0)  # turning 3 times about z
    limits = MissionLimits(vehicle=vehicle)
    result, seq, reason = check_mission([*START, fig], limits)
    assert (result, seq) == (M.MAV_MISSION_DENIED, 1)
    assert reason.startswith("item 1: tilt servo ") and "limit 3.0 (75% of 4.0)" in reason
    proposed = float(reason.split("lengthen p2 to ")[1][:-2])
    longer = [*START, fig._replace(param2=proposed)]
    assert check_mission(longer, limits).result == M.MAV_MISSION_ACCEPTED
    ex = started(longer, limits)
    t0, t1 = ex.schedule[1][1:]
    # inside the item (its end's step into the hold is the step check's)
    assert dense_tilt_rate(envelope(vehicle), ex, t0 + 1e-3, t1 - 4e-3, dt=2e-3) <= \
        envelope(vehicle).tilt_limit * 1.01


# ----------------------------------------------------------------------------------------
# Thrust reversal: a braking climb on planar rotors
# ----------------------------------------------------------------------------------------

LEVEL = (1.0, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("height_m", [0.2, 0.3, 0.5])
def test_a_climb_that_brakes_beyond_g_does_not_fit_on_planar_rotors(height_m):
    """Given a vertical climb of 0.2-0.5 m at the default take-off speed (1 m/s) on the planar
    preset, whose quintic brakes at 5.77 h / D^2 > g (the thrust must reverse: every tilt turns
    half a revolution between two samples, though its derivative is zero at each), then it does
    not fit, naming a tilt servo; the shortest duration that fits brakes at under g and keeps
    every rotor above the floor; and judged without the sample-to-sample turns (the check of
    before) the reversing climb is taken for flyable."""
    from fcu.envelope.feasibility import FLOOR, TILT_STEP_S
    env = envelope(PLANAR)
    seg = _Move(0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, height_m), LEVEL, None, height_m / 1.0, 0.0)
    sc = env.scaling(seg)
    excess = sc.excess(seg.travel)
    assert excess.ratio > 10.0 and excess.kind == "tilt servo", excess
    assert 5.77 * height_m / seg.travel ** 2 > PLANAR.gravity_m_s2
    shortest = sc.shortest()
    assert math.isfinite(shortest) and shortest > seg.travel
    assert 5.7735 * height_m / shortest ** 2 < 0.95 * PLANAR.gravity_m_s2
    assert sc.speeds(shortest).min() >= FLOOR * PLANAR.rotor_speed_max_rad_s * (1 - 1e-3)
    ratio, *_ = excess_kernel(sc.om0, sc.om1, sc.dom0, sc.dom1, sc.is_end, seg.travel,
                              env.limit, env.tau_up, env.tau_down, env.tilt_limit,
                              env.tilt_rate_max * TILT_STEP_S)
    assert ratio < 2.0  # blind to the reversal without the neighbours


def test_a_rotor_slowed_below_the_floor_is_named():
    """Given the planar climb of 0.5 m flown 1 % faster than its shortest duration, then the
    excess is the rotor floor (25 % of 1700 rad/s), explained with the speed it would slow
    to; 10 % faster the thrust reverses and a tilt servo is named."""
    env = envelope(PLANAR)
    seg = _Move(0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.5), LEVEL, None, 0.5, 0.0)
    sc = env.scaling(seg)
    excess = sc.excess(sc.shortest() * 0.99)
    assert excess.kind == "rotor floor" and 1.0 < excess.ratio < 1.5, excess
    assert excess.limit == pytest.approx(425.0) and excess.need < 425.0
    assert env.explain(excess) == (f"rotor {excess.number} slows to {excess.need:.0f} rad/s, "
                                   "floor 425 (25% of 1700: its thrust would near zero or "
                                   "reverse)")
    assert sc.excess(sc.shortest() * 0.9).kind == "tilt servo"
