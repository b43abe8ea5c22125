"""The commander's landing (fcu/modes/commander.py): the set-point sinks below the planned end of
the descent until the land detector sees the vehicle held up and still, then disarms; a
vehicle still in the air is never taken for landed."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_gains, load_vehicle
from common.outcome import CRASH, FAILSAFE
from common.wire.mav_enums import MAV_CMD, MAV_FRAME, MAV_RESULT
from common.wire.mission_items import MissionItem
from common.wire.modes import Mode
from fcu.control.dualquat import norm3 as norm
from fcu.edge.setpoint_wire import attitude_target, position_target, sticks_from_manual_control
from fcu.mission.limits import MissionLimits
from fcu.modes import manual
from fcu.modes.landing import (
    LANDED_STILL_S,
    TOUCHDOWN_BELOW_M,
    TOUCHDOWN_DEPTH_M,
    TOUCHDOWN_RAMP_S,
    touchdown_speed_cap,
)
from fcu.modes.manual import StickSettings
from fcu.modes.settings import FlightSettings
from fcu.pipeline import Pipeline
from fcu.safety.failsafe import FailsafeSettings
from fcu.stages import Reference, VehicleState, pose_ref

ROOT = Path(__file__).resolve().parents[2]


def _state(z: float, vz: float = 0.0) -> VehicleState:
    return VehicleState((1.0, 2.0, z), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, vz), (0.0, 0.0, 0.0))


def _landing_pipeline(z0: float) -> Pipeline:
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    limits=MissionLimits(land_speed_m_s=0.5))
    pipe.on_state(0, _state(z0), 0)
    assert pipe.arm()[0] == 0
    assert pipe.commander.set_mode(Mode.LAND, 0.0)[0] == 0
    return pipe


def test_touchdown_set_point_sinks_below_the_plan_then_stops():
    """Given LAND from 2 m at 0.5 m/s, when the planned descent has ended and the vehicle
    follows its set-point (no ground below), then the set-point keeps sinking, its speed
    reached from rest over TOUCHDOWN_RAMP_S (no step: 0.1 s after, 1 cm lower), at the land
    speed at most TOUCHDOWN_DEPTH_M below the plan's end, and nothing disarms a vehicle
    that moves."""
    pipe = _landing_pipeline(2.0)
    c = pipe.commander
    t = 0
    while c.modes.descent.touchdown is None:
        t += 2000
        pipe.on_state(t, _state(0.3, -0.3), t)  # in the air, still descending
        pipe.step(t)
        assert t < 20_000_000
    end = c.modes.descent.touchdown
    samples, speeds = [], []
    z = end.p_enu_m[2]
    for _ in range(2000):  # 4 s
        t += 2000
        pipe.on_state(t, _state(z, -0.3), t)
        out = pipe.step(t)
        z = c.last_ref.p_enu_m[2]  # the vehicle follows its set-point
        samples.append(z)
        speeds.append(-c.last_ref.v_enu_m_s[2])
        assert out.armed  # moving: not landed
    dt = 0.1
    assert samples[49] == pytest.approx(end.p_enu_m[2] - 0.5 * dt * dt / (2 * TOUCHDOWN_RAMP_S))
    assert max(np.diff(speeds)) <= 0.5 * 0.002 / TOUCHDOWN_RAMP_S + 1e-12  # ramped
    assert max(speeds) == pytest.approx(0.5)
    assert min(samples) == end.p_enu_m[2] - TOUCHDOWN_DEPTH_M


def test_touchdown_set_point_stays_just_below_a_vehicle_held_up():
    """Given the touchdown phase and a vehicle held 0.3 m above the plan's end (the ground is
    higher than planned), then the set-point never goes more than TOUCHDOWN_BELOW_M below
    the vehicle, however long it sinks (it does not sink on into the ground)."""
    pipe = _landing_pipeline(2.0)
    c = pipe.commander
    start = _to_touchdown(pipe, 0.3)
    t = start
    lowest = math.inf
    while pipe.armed and t - start < 3_000_000:
        t += 2000
        pipe.on_state(t, _state(0.3), t)
        pipe.step(t)
        lowest = min(lowest, c.last_ref.p_enu_m[2])
    assert lowest == pytest.approx(0.3 - TOUCHDOWN_BELOW_M)


def _to_touchdown(pipe: Pipeline, z: float) -> int:
    """Step through the planned descent with the vehicle held at height z; the time the
    touchdown phase starts."""
    t = 0
    while pipe.commander.modes.descent.touchdown is None:
        t += 2000
        pipe.on_state(t, _state(z), t)
        pipe.step(t)
        assert pipe.armed and t < 20_000_000
    return t


def test_land_detector_needs_the_vehicle_held_up():
    """Given the touchdown phase with the set-point below the vehicle by more than 0.1 m
    (something holds it up: the ground, a stand), when the vehicle stays still, then it is
    landed after LANDED_STILL_S and disarms, with no crash recorded."""
    pipe = _landing_pipeline(0.3)
    start = _to_touchdown(pipe, 0.3)  # the plan ends on the ground, 0.3 m below
    t = start
    while pipe.armed:
        t += 2000
        pipe.on_state(t, _state(0.3), t)
        pipe.step(t)
        assert t - start < 4_000_000
    # the push that tells the ground builds up with the sink's ramp
    assert start + LANDED_STILL_S * 1e6 <= t <= \
        start + (LANDED_STILL_S + TOUCHDOWN_RAMP_S) * 1e6 + 4000
    texts = [e.text for e in pipe.events]
    assert "landed: disarmed" in texts and "disarmed in the air" not in texts


def test_a_set_point_just_below_is_not_support():
    """Given the touchdown phase and a still vehicle with zero lift, when the set-point is
    only 5 cm below it (less than TOUCHDOWN_BLOCKED_M) and the vehicle is above ground level,
    then the land detector does not call it landed."""
    pipe = _landing_pipeline(0.3)
    start = _to_touchdown(pipe, 0.3)
    c = pipe.commander
    c.last_ref = pose_ref((1.0, 2.0, 0.25), c.modes.descent.touchdown.q_enu_flu)
    for t in range(start, start + 1_000_000, 2000):
        assert not c.land_detector(t, 0.0, pipe.weight_n)
    assert not c.landed


def test_an_armed_vehicle_leaves_the_ground_when_it_rises_or_moves():
    """Given a vehicle on the ground, armed, when a state 0.5 m up arrives (or one at ground
    level climbing at 0.5 m/s), then it is not landed: a plain disarm is refused and a forced
    one is recorded as a disarm in the air."""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    for z, vz in ((0.5, 0.0), (0.02, 0.5)):
        pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500)
        pipe.on_state(0, _state(0.0), 0)
        assert pipe.commander.landed
        pipe.arm()
        pipe.on_state(2000, _state(z, vz), 2000)
        assert not pipe.commander.landed
        assert pipe.commander.disarm()[0] == MAV_RESULT.MAV_RESULT_DENIED
        pipe.commander.disarm(force=True)
        assert any(e.kind == CRASH for e in pipe.events)


def test_saturation_is_monitored_in_the_step():
    """Given an offboard target 30 m away and a vehicle that does not move (the reference
    leaves it and the rotors saturate) and COM_SAT_T = 0.2 s, when the pipeline steps for
    4 s (the approach starts smoothly: 7 m by then), then the saturation is counted and
    reported."""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    failsafes=FailsafeSettings(saturation_s=0.2, divergence_m=1000.0))
    pipe.on_state(0, _state(5.0), 0)
    pipe.arm()
    c = pipe.commander
    assert c.offboard_position(0.0, position_target(1, 0, (30.0, 0.0, -5.0), (0.0, 0.0, 0.0),
                               (0.0, 0.0, 0.0), 0.0))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    for t in range(0, 4_000_000, 2000):
        pipe.on_state(t, _state(5.0), t)
        pipe.step(t, 0.002)
    assert pipe.saturated_steps > 100 and pipe.failsafe == "rotor saturation"
    assert any(e.text.startswith("rotors saturated") for e in pipe.events)


# ------------------------------------------------------------------ TAKEOFF, RTL, POSCTL


def _kinematic(pipe: Pipeline, t0: int, seconds: float, sticks=None, now_s=None,
               ground: bool = True) -> list[tuple[int, tuple[float, float, float], str]]:
    """Step the pipeline with a vehicle that is where it was told to be (held at z >= 0
    when `ground`); (t, position, mode) per step."""
    c = pipe.commander
    out = []
    t = t0
    for _ in range(round(seconds * 500)):
        t += 2000
        if sticks is not None:
            c.manual_input(now_s(t) if now_s else 0.0,
                           sticks_from_manual_control(*sticks(t * 1e-6)))
        pipe.step(t)
        ref = c.last_ref if pipe.armed and c.last_ref is not None else None
        p = ref.p_enu_m if ref is not None else pipe.state.p_enu_m
        if ground:
            p = (p[0], p[1], max(0.0, p[2]))
        q = ref.q_enu_flu if ref is not None else pipe.state.q_enu_flu
        pipe.on_state(t, VehicleState(p, q, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), t)
        out.append((t, p, c.mode.name))
    return out


def _on_ground(flight=None) -> Pipeline:
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    limits=MissionLimits(vehicle=vehicle))
    if flight is not None:
        pipe.commander.flight = flight
    pipe.on_state(0, VehicleState((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    return pipe


def test_takeoff_climbs_mis_takeoff_alt_then_holds():
    """Given a vehicle armed on the ground, when NAV_TAKEOFF comes without an altitude, then
    the mode is TAKEOFF, the set-point climbs MIS_TAKEOFF_ALT (2.5 m) straight up (at most
    MIS_TKO_SPD), and the mode becomes HOLD there; disarmed, it is refused."""
    pipe = _on_ground()
    c = pipe.commander
    assert c.takeoff()[0] == MAV_RESULT.MAV_RESULT_DENIED  # not armed
    assert pipe.arm()[0] == 0
    assert c.takeoff()[0] == 0 and c.mode == Mode.TAKEOFF and c.flight_started
    trace = _kinematic(pipe, 0, 5.0)
    t_hold = next(t for t, _, mode in trace if mode == "HOLD")
    assert t_hold * 1e-6 >= 1.875 * 2.5 / 1.0  # 2.5 m at up to MIS_TKO_SPD 1 m/s
    for _, p, _ in trace:
        assert p[0] == 0.0 and p[1] == 0.0 and 0.0 <= p[2] <= 2.5 + 1e-9
    assert trace[-1][1][2] == pytest.approx(2.5) and trace[-1][2] == "HOLD"
    assert "takeoff complete: mode HOLD" in [e.text for e in pipe.events]


def test_takeoff_to_an_altitude_and_below_the_minimum():
    """Given a target altitude 4 m above home, then the climb is to 4 m; given one below the
    vehicle (MAVProxy's `takeoff 5` as AMSL), then MIS_TAKEOFF_ALT is climbed, with a
    warning (as PX4 raises it to its minimum)."""
    pipe = _on_ground()
    c = pipe.commander
    pipe.arm()
    assert c.takeoff(4.0)[0] == 0
    assert _kinematic(pipe, 0, 8.0)[-1][1][2] == pytest.approx(4.0)
    pipe = _on_ground()
    pipe.arm()
    assert pipe.commander.takeoff(-483.0)[0] == 0
    assert _kinematic(pipe, 0, 5.0)[-1][1][2] == pytest.approx(2.5)
    assert any("minimum climb" in e.text for e in pipe.events)


def test_rtl_climbs_flies_home_and_touches_down():
    """Given the vehicle 4 m north-east-ish of home at 2 m, when RTL starts, then the
    set-point climbs to RTL_RETURN_ALT (only up), then travels level to above home, then
    descends there, and the land detector disarms on the ground; nothing overshoots."""
    flight = FlightSettings(rtl_return_alt_m=5.0, rtl_cruise_m_s=2.0)
    pipe = _on_ground(flight)
    c = pipe.commander
    pipe.on_state(0, VehicleState((3.0, 2.0, 2.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    assert c.set_mode(Mode.RTL, 0.0)[0] == MAV_RESULT.MAV_RESULT_DENIED  # not armed
    pipe.arm()
    assert c.set_mode(Mode.RTL, 0.0)[0] == 0 and c.mode == Mode.RTL and c.landing
    trace = _kinematic(pipe, 0, 30.0)
    heights = [p[2] for _, p, _ in trace]
    top = heights.index(max(heights))
    assert max(heights) == pytest.approx(5.0)
    assert all(p[:2] == (3.0, 2.0) for _, p, _ in trace[:top])  # straight up first
    assert all(math.isclose(p[2], 5.0) for _, p, _ in trace if 0.1 < math.hypot(*p[:2]) <
               math.hypot(3.0, 2.0) - 0.1)  # level travel
    assert all(math.hypot(*p[:2]) <= math.hypot(3.0, 2.0) + 1e-9 for _, p, _ in trace)
    assert not pipe.armed and trace[-1][1] == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
    assert "landed: disarmed" in [e.text for e in pipe.events]
    assert not any(e.kind == CRASH for e in pipe.events)


def test_rtl_flies_at_up_to_its_speeds_and_no_faster():
    """Given the vehicle 40 m from home at 3 m, when RTL starts (MPC_XY_CRUISE 5 m/s,
    MIS_TKO_SPD 1, MIS_LAND_SPD 0.5), then its reference climbs at up to 1 m/s, travels home
    at up to 5 m/s and descends at up to 0.5 m/s, each reached (within 1 %) and never
    exceeded: the speeds are top speeds, as PX4's are. (Timed as means, the return peaked at
    9.4 m/s.)"""
    pipe = _on_ground(FlightSettings(rtl_return_alt_m=6.0, rtl_cruise_m_s=5.0))
    c = pipe.commander
    pipe.on_state(0, VehicleState((24.0, 32.0, 3.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    pipe.arm()
    assert c.set_mode(Mode.RTL, 0.0)[0] == 0
    up = level = down = 0.0
    t = 0
    while c.last_ref is None or math.hypot(*c.last_ref.p_enu_m[:2]) > 0.0 or \
            c.last_ref.p_enu_m[2] > 0.5:
        t += 2000
        assert t < 120_000_000
        pipe.step(t)
        ref = c.last_ref
        assert ref is not None
        v = ref.v_enu_m_s
        up, level, down = max(up, v[2]), max(level, math.hypot(v[0], v[1])), max(down, -v[2])
        pipe.on_state(t, VehicleState(ref.p_enu_m, ref.q_enu_flu, (0.0,) * 3, (0.0,) * 3), t)
    assert 0.99 <= up <= 1.0 + 1e-9
    assert 4.95 <= level <= 5.0 + 1e-9
    assert 0.495 <= down <= 0.5 + 1e-9


def _climbing_at_six_metres_per_second(
        east_m: float = 4.0, up_m: float = 60.0) -> tuple[Pipeline, int, Reference]:
    """A mission flying from (4, 3, 2) m ENU to (east_m, 3, up_m) m (default: straight up
    to 60 m) at up to 12 m/s (RTL_RETURN_ALT 5 m), sampled until its reference moves at
    6 m/s, still speeding up: the pipeline, the time, the reference then."""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    limits=MissionLimits(vehicle=vehicle, cruise_speed_m_s=12.0))
    c = pipe.commander
    c.flight = FlightSettings(rtl_return_alt_m=5.0)
    pipe.on_state(0, VehicleState((4.0, 3.0, 2.0), (1.0, 0.0, 0.0, 0.0), (0.0,) * 3,
                                  (0.0,) * 3), 0)
    assert pipe.arm()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    c.set_mission((MissionItem(0, MAV_FRAME.MAV_FRAME_LOCAL_NED,
                               MAV_CMD.MAV_CMD_NAV_WAYPOINT, 1, 1, 0.0, 0.0, 0.0, math.nan,
                               30_000, round(east_m * 1e4), -up_m),))
    assert c.set_mode(Mode.MISSION, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    t = 0
    while math.hypot(*c.fly(t).v_enu_m_s) < 6.0:
        t += 2000
        assert t < 20_000_000
    entry = c.fly(t)
    assert math.hypot(*entry.a_enu_m_s2) > 0.5  # still speeding up
    return pipe, t, entry


def test_takeoff_asked_in_a_fast_climb_climbs_no_more_where_its_brake_stops_above():
    """Given the fast climb, when TAKEOFF comes (2.5 m up from there), then the brake stops
    far above that target and TAKEOFF ends there, holding: the reference never comes down
    (the climb planned where TAKEOFF came flew it 13 m back down to its target)."""
    pipe, t, entry = _climbing_at_six_metres_per_second()
    c = pipe.commander
    assert c.takeoff()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    path = [c.fly(t + 2000 * k) for k in range(1, 10 * 500)]
    rest = next(k for k, r in enumerate(path) if r.v_enu_m_s == (0.0, 0.0, 0.0))
    assert path[rest].p_enu_m[2] > entry.p_enu_m[2] + 2.5 + 5.0
    assert all(r.p_enu_m == path[rest].p_enu_m for r in path[rest:])
    assert c.mode == Mode.HOLD and "takeoff complete: mode HOLD" in [e.text for e in pipe.events]


def test_takeoff_asked_in_fast_flight_holds_where_its_brake_stops_if_the_climb_leaves_the_fence():
    """Given a mission flying east at 2 m at 6 m/s and speeding up, and GF_MAX_DIST set to
    15 m, when TAKEOFF comes (2.5 m up: its target 10.2 m from home where it is asked,
    inside), then HOLD's brake stops 20.8 m east; TAKEOFF checks its climb again there,
    refuses it with a warning and holds where the brake stopped: the reference never
    climbs (checked only where TAKEOFF came, it climbed to 4.5 m there, 21.5 m from home)."""
    pipe, t, entry = _climbing_at_six_metres_per_second(east_m=60.0, up_m=2.0)
    c = pipe.commander
    c.configure(replace(c.limits, max_distance_m=15.0), c.offboard_timeout_s, None)
    assert math.hypot(entry.p_enu_m[0], entry.p_enu_m[1], entry.p_enu_m[2] + 2.5) < 15.0
    assert c.takeoff()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    path = [c.fly(t + 2000 * k) for k in range(1, 10 * 500)]
    rest = next(k for k, r in enumerate(path) if r.v_enu_m_s == (0.0, 0.0, 0.0))
    stop = path[rest].p_enu_m
    assert math.hypot(stop[0], stop[1], stop[2] + 2.5) > 15.0  # its climb: beyond
    assert max(r.p_enu_m[2] for r in path) == pytest.approx(2.0, abs=1e-9)
    assert all(r.p_enu_m == stop for r in path[rest:])
    said = [e.text for e in pipe.events]
    assert "takeoff: climb beyond GF_MAX_DIST: holding" in said
    assert c.mode == Mode.HOLD and "takeoff complete: mode HOLD" in said


def test_rtl_asked_in_a_fast_climb_returns_from_where_its_brake_stops():
    """Given a mission climbing at 6 m/s and still speeding up, when RTL comes (return
    altitude 5 m, below), then the reference brakes to rest above where RTL came and
    returns home from that height, never coming down before it is above home (RTL's
    plan made where RTL came had it sink back to that height first), and it says the new
    return altitude."""
    pipe, t, entry = _climbing_at_six_metres_per_second()
    c = pipe.commander
    assert c.set_mode(Mode.RTL, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    path = [c.fly(t + 2000 * k) for k in range(1, 40 * 500)]
    rest = next(k for k, r in enumerate(path) if r.v_enu_m_s == (0.0, 0.0, 0.0))
    top = path[rest].p_enu_m[2]
    assert top > entry.p_enu_m[2] + 1.0
    home = next(k for k, r in enumerate(path) if math.hypot(*r.p_enu_m[:2]) < 1e-9)
    heights = [r.p_enu_m[2] for r in path[rest:home + 1]]
    assert all(b >= a - 1e-9 for a, b in itertools.pairwise(heights))
    assert path[home].p_enu_m[2] == pytest.approx(top)
    said = [e.text for e in pipe.events if e.text.startswith("RTL: return at")]
    assert said == [f"RTL: return at {entry.p_enu_m[2]:.1f} m, then land",
                    f"RTL: return at {top:.1f} m"]


def test_rtl_above_the_return_altitude_does_not_climb():
    pipe = _on_ground(FlightSettings(rtl_return_alt_m=1.0))
    pipe.on_state(0, VehicleState((0.0, 2.0, 3.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    pipe.arm()
    assert pipe.commander.set_mode(Mode.RTL, 0.0)[0] == 0
    assert max(p[2] for _, p, _ in _kinematic(pipe, 0, 3.0)) == pytest.approx(3.0)


def test_posctl_needs_manual_control_and_falls_back_to_hold():
    """POSCTL is refused without a MANUAL_CONTROL stream; with one, the sticks move the
    set-point (forward = the heading: east for the identity attitude), and when the stream
    stops for COM_RC_LOSS_T (wall clock) the vehicle holds, with a failsafe."""
    pipe = _on_ground()
    c = pipe.commander
    pipe.on_state(0, VehicleState((0.0, 0.0, 2.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    assert c.set_mode(Mode.POSCTL, 10.0)[0] == MAV_RESULT.MAV_RESULT_DENIED
    c.manual_input(10.0, sticks_from_manual_control(0, 0, 500, 0))
    assert c.set_mode(Mode.POSCTL, 10.2)[0] == 0
    pipe.arm()
    assert c.flight_started
    trace = _kinematic(pipe, 0, 4.0, sticks=lambda t: (1000 if t < 2.0 else 0, 0, 500, 0),
                       now_s=lambda t: 10.0 + t * 1e-6, ground=False)
    end = trace[-1][1]
    # about 5 m/s x 2 s: the ramps, at the jerk the tilt servos allow, nearly cancel
    assert end[0] == pytest.approx(2 * 5.0, rel=0.1) and abs(end[1]) < 1e-9  # east
    assert end[2] == pytest.approx(2.0)
    pipe.check_links(14.3)
    assert c.mode == Mode.POSCTL
    pipe.check_links(14.6)  # 0.6 s after the last MANUAL_CONTROL
    assert c.mode == Mode.HOLD and pipe.events[-1].kind == FAILSAFE
    assert c.modes.brake.hold.p_enu_m == pytest.approx(end)


# ------------------------------------------------------------------ OFFBOARD


def test_offboard_approaches_a_pose_from_the_reference_flown_without_a_yaw_stick():
    """Given MPC_MAN_Y_MAX = 0 (no yaw stick) and a vehicle that follows its reference, when
    OFFBOARD gets a pose 10 m north at a heading of 120 deg (it faces east: 90 deg), then
    the reference starts where the vehicle is, moves at most MPC_VEL_MANUAL, turns
    (OFFBOARD's rotation limit is its own) and ends on the pose; a new sample 2 m further
    is approached from there, no jump."""
    from common.quaternion import q_angle, q_conj, q_exp, q_mul

    pipe = _on_ground(FlightSettings(sticks=StickSettings(yaw_rate_deg_s=0.0)))
    c = pipe.commander
    pipe.on_state(0, VehicleState((0.0, 0.0, 3.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                  (0.0, 0.0, 0.0)), 0)
    assert pipe.arm()[0] == 0
    q_ned_frd = (0.5, 0.0, 0.0, math.sqrt(0.75))  # 120 deg clockwise seen from above
    assert c.offboard_position(0.0, position_target(1, 0b0000_1101_1111_1000, (10.0, 0.0, -3.0),
                               (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    assert c.offboard_attitude(0.0, attitude_target(0b0100_0111, q_ned_frd, (0.0,) * 3))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    track = _kinematic(pipe, 0, 12.0, ground=False)
    p = [x[1] for x in track]
    assert math.dist(p[0], (0.0, 0.0, 3.0)) < 1e-3
    steps = [math.dist(a, b) * 500 for a, b in itertools.pairwise(p)]
    # at most MPC_VEL_MANUAL; the tilt servos (the envelope) bind first here, at 4.3 m/s
    assert max(steps) <= 5.0 + 1e-6 and max(steps) > 4.0
    assert math.dist(p[-1], (0.0, 10.0, 3.0)) < 1e-6  # NED north is ENU y
    q_want = q_exp((0.0, 0.0, math.radians(90.0 - 120.0)))  # ENU yaw = 90 deg - NED yaw
    assert q_angle(q_mul(q_conj(q_want), c.last_ref.q_enu_flu)) < 1e-5
    assert c.offboard_position(0.0, position_target(1, 0b0000_1101_1111_1000, (12.0, 0.0, -3.0),
                               (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    more = [x[1] for x in _kinematic(pipe, track[-1][0], 6.0, ground=False)]
    assert math.dist(more[0], p[-1]) < 1e-4 and math.dist(more[-1], (0.0, 12.0, 3.0)) < 1e-3


def test_rearmed_in_offboard_the_approach_starts_where_the_vehicle_is():
    """Given OFFBOARD flying toward a pose 10 m north, when the vehicle is disarmed in the air
    (a kill) and re-armed on the ground 5 m away, then the first reference is where the
    vehicle is, at rest: nothing shaped before the disarm is flown on."""
    pipe = _on_ground()
    c = pipe.commander
    assert pipe.arm()[0] == 0
    assert c.offboard_position(0.0, position_target(1, 0b0000_1101_1111_1000, (10.0, 0.0, -3.0),
                               (0.0,) * 3, (0.0,) * 3, 0.0))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    track = _kinematic(pipe, 0, 1.5)
    assert c.last_ref is not None and norm(c.last_ref.v_enu_m_s) > 1.0  # under way
    assert c.disarm(force=True).result == MAV_RESULT.MAV_RESULT_ACCEPTED
    t = track[-1][0] + 2_000_000
    ground = (5.0, -5.0, 0.0)
    pipe.on_state(t, VehicleState(ground, (1.0, 0.0, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3), t)
    assert pipe.arm()[0] == 0 and c.mode is Mode.OFFBOARD
    pipe.step(t + 2000)
    assert c.last_ref is not None
    assert math.dist(c.last_ref.p_enu_m, ground) < 1e-3, c.last_ref.p_enu_m
    assert norm(c.last_ref.v_enu_m_s) < 1e-2, c.last_ref.v_enu_m_s


@pytest.mark.parametrize("mode", [Mode.HOLD, Mode.LAND, Mode.RTL, Mode.TAKEOFF, Mode.POSCTL,
                                  Mode.MISSION])
def test_a_mode_entered_during_a_missions_descent_speeding_up_brakes_first(mode):
    """Given a mission at 3.75 m/s descending 18 m over 3 m (faster down than the approach
    limits' 1.5 m/s), when HOLD, LAND, RTL, TAKEOFF, POSCTL (sticks centred) or a
    new current item comes while the leg still speeds up, then the reference's velocity
    goes on from the mission's (no step), and it comes to rest within 3 s and 2 m of where
    the mode came, never below 17 m, before flying the mode's plan from there. (HOLD's
    brake dived through the ground at 16 m/s: every brake overshot the entry's descent
    speed, none fitted, and the longest tried, 120 s, was flown. The others started at
    rest at once: the reference's velocity stepped from 1.9 m/s to zero.)"""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    limits=MissionLimits(vehicle=vehicle, cruise_speed_m_s=3.75))
    pipe.on_state(0, _state(20.0), 0)
    assert pipe.arm()[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    c = pipe.commander
    c.set_mission((MissionItem(0, MAV_FRAME.MAV_FRAME_LOCAL_NED,
                               MAV_CMD.MAV_CMD_NAV_WAYPOINT, 1, 1, 0.0, 0.0, 0.0, math.nan,
                               30_000, 0, -2.0),))  # 3 m north, 2 m up (x in 1e-4 m)
    assert c.set_mode(Mode.MISSION, 0.0)[0] == MAV_RESULT.MAV_RESULT_ACCEPTED
    t = 0
    while math.dist(c.fly(t).v_enu_m_s, (0.0, 0.0, 0.0)) < 1.8:
        t += 2000
        assert t < 20_000_000
    entry = c.fly(t)
    assert entry.v_enu_m_s[2] < -1.5 and entry.a_enu_m_s2[2] < -0.5  # still speeding up
    c.manual_input(0.0, manual.CENTRED)
    answer = c.takeoff() if mode == Mode.TAKEOFF else c.set_mission_current(0) \
        if mode == Mode.MISSION else c.set_mode(mode, 0.0)
    assert answer[0] == (MAV_RESULT.MAV_RESULT_IN_PROGRESS if mode == Mode.MISSION else
                         MAV_RESULT.MAV_RESULT_ACCEPTED) and c.mode == mode
    path = [c.fly(t + 2000 * k) for k in range(1, 10 * 500)]
    assert math.dist(path[0].v_enu_m_s, entry.v_enu_m_s) < 0.01
    rest = next(k for k, r in enumerate(path) if math.dist(r.v_enu_m_s, (0.0, 0.0, 0.0)) == 0)
    assert rest < 3 * 500
    assert min(r.p_enu_m[2] for r in path[:rest + 1]) > 17.0
    assert math.dist(path[rest].p_enu_m, entry.p_enu_m) < 2.0
    if mode in (Mode.HOLD, Mode.POSCTL):
        assert all(r.p_enu_m == path[rest].p_enu_m for r in path[rest:])
    else:  # its plan flies on from the rest
        assert math.dist(path[-1].p_enu_m, path[rest].p_enu_m) > 0.2


def test_land_rearmed_after_landing_holds_where_it_is():
    """Given a vehicle that landed in LAND and disarmed, when it is re-armed (the mode stays
    LAND) and LAND is asked again, then no descent is planned: it holds where it is."""
    pipe = _landing_pipeline(0.3)
    c = pipe.commander
    t = _to_touchdown(pipe, 0.3)  # the plan ends on the ground, 0.3 m below
    while pipe.armed:
        t += 2000
        pipe.on_state(t, _state(0.3), t)
        pipe.step(t)
        assert t < 30_000_000, "never landed"
    assert c.mode is Mode.LAND and pipe.arm()[0] == 0
    assert c.set_mode(Mode.LAND, t * 1e-6)[0] == 0
    assert c.modes.descent.plan is None and c.modes.descent.touchdown is None
    for _ in range(50):
        t += 2000
        pipe.on_state(t, _state(0.3), t)
        pipe.step(t)
        assert c.last_ref is not None and c.last_ref.p_enu_m == pytest.approx((1.0, 2.0, 0.3))


def test_a_land_speed_the_gains_cannot_land_at_is_capped_and_said():
    """Given MIS_LAND_SPD 3 m/s and the default gains (k_d 10 /s), when the touchdown phase
    starts, then the set-point sinks at TOUCHDOWN_PUSH g / k_d (0.59 m/s), not 3 m/s, and the
    vehicle says so once; at 0.5 m/s nothing is capped or said."""
    pipe = _landing_pipeline(2.0)
    cap = touchdown_speed_cap(10.0, 9.81)
    assert cap == pytest.approx(0.5886)
    pipe.commander.limits = MissionLimits(land_speed_m_s=3.0)
    start = _to_touchdown(pipe, 1.0)
    t = start
    for _ in range(500):
        t += 2000
        pipe.on_state(t, _state(1.0), t)
        pipe.step(t)
    c = pipe.commander
    assert c.touchdown_speed_m_s == pytest.approx(cap, rel=1e-3)
    assert -c.last_ref.v_enu_m_s[2] == pytest.approx(c.touchdown_speed_m_s)
    said = [e.text for e in pipe.events if e.text.startswith("touchdown capped")]
    assert said == ["touchdown capped at 0.59 m/s (MIS_LAND_SPD 3.00)"]
    slow = _landing_pipeline(2.0)
    _to_touchdown(slow, 1.0)
    assert slow.commander.touchdown_speed_m_s == 0.5
    assert not [e for e in slow.events if e.text.startswith("touchdown capped")]


def test_a_refused_arming_is_said_once_in_the_vehicles_words():
    """`fcu.compose.arm_and_start` (in-process runs) gives the vehicle's own refusal, not
    'arming refused: arming refused: ...'."""
    from fcu.compose import arm_and_start
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500)
    assert arm_and_start(pipe) == "arming refused: no state input"


def test_the_failsafe_in_force_is_a_member_whose_value_the_logs_and_texts_name():
    """`Pipeline.failsafe` is a `Failsafe` member: NONE is empty and false; the others are
    true and read as the words the logs, STATUSTEXTs and metrics carry."""
    from fcu.safety.failsafe import CRITICAL_FAILSAFES, Failsafe
    assert not Failsafe.NONE and str(Failsafe.GCS_LOST) == "GCS link lost"
    assert all(f and f.value for f in Failsafe if f is not Failsafe.NONE)
    assert set(CRITICAL_FAILSAFES) == {Failsafe.DIVERGED, Failsafe.NON_FINITE}
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500)
    assert pipe.failsafe is Failsafe.NONE
