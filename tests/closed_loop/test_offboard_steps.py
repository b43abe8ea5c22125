"""OFFBOARD steps of any size flown by the FCU's pipeline over the plant: the vehicle
approaches the streamed pose at bounded speed and reaches it, instead of taking the step as
a tracking error (a 10 m, 150 deg step once saturated the rotors and put it on the ground,
and a ground station's `goto` from the middle of a mission then failed)."""

from __future__ import annotations

import math

import pytest

from common.config.scenario import load_scenario
from common.frames import ned_to_enu, q_enu_flu_to_ned_frd, q_ned_frd_to_enu_flu
from common.quaternion import q_angle, q_conj, q_mul
from common.wire.mav_enums import ATTITUDE_TARGET_TYPEMASK as ATT
from common.wire.mav_enums import POSITION_TARGET_TYPEMASK as POS
from common.wire.modes import Mode
from common.wire.simlink import through_wire_controls
from fcu.edge.setpoint_wire import (
    ACCELERATION_IGNORE,
    RATES_IGNORE,
    VELOCITY_IGNORE,
    attitude_target,
    position_target,
)
from fcu.edge.sim_bridge import actuator_controls
from gcs.run.inprocess import fcu_pipeline, state_for_fcu
from gcs.vehicle_link.pose import PoseTarget
from sitl.plant import Plant, hover_speeds_and_tilts
from sitl.world import command_from_controls

from .conftest import SCENARIOS

# SET_POSITION_TARGET_LOCAL_NED: the position only (no velocity, acceleration, yaw, yaw rate)
POSITION_ONLY = VELOCITY_IGNORE | ACCELERATION_IGNORE | \
    POS.POSITION_TARGET_TYPEMASK_YAW_IGNORE | POS.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
# SET_ATTITUDE_TARGET: the attitude, no rates, no thrust
ATTITUDE_ONLY = RATES_IGNORE | ATT.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE


def fly_offboard(start_enu_m, target: PoseTarget, seconds: float) -> dict:
    """Hovering at `start_enu_m`, armed, OFFBOARD to `target` (a fresh stream throughout);
    figures of the flight."""
    sc = load_scenario(SCENARIOS / "case1_figure8.toml")
    vehicle = sc.vehicle
    plant = Plant(vehicle, dt_us=1000)
    speeds, tilts = hover_speeds_and_tilts(plant)
    state = plant.initial_state(start_enu_m, on_ground=False, rotor_speed_rad_s=speeds,
                                tilt_rad=tilts)
    pipe, _ = fcu_pipeline(sc)
    c = pipe.commander
    pipe.on_state(0, state_for_fcu(state), 0)
    assert pipe.arm()[0] == 0
    assert c.offboard_position(0.0, position_target(1, POSITION_ONLY, target.p_ned_m, (0.0,) * 3,
                                                    (0.0,) * 3, 0.0))[0]
    assert c.offboard_attitude(0.0, attitude_target(ATTITUDE_ONLY, target.q_ned_frd,
                                                    (0.0,) * 3))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    p_t, q_t = ned_to_enu(target.p_ned_m), q_ned_frd_to_enu_flu(target.q_ned_frd)
    track_m = track_rad = 0.0
    reached_s = math.nan
    speed = 0.0
    for _ in range(round(seconds * 500)):
        t = state.time_us
        pipe.on_state(t, state_for_fcu(state), t)
        out = pipe.step(t, 0.002)
        ref = c.last_ref
        track_m = max(track_m, math.dist(ref.p_enu_m, state.p_enu_m))
        track_rad = max(track_rad, q_angle(q_mul(q_conj(ref.q_enu_flu), state.q_enu_flu)))
        speed = max(speed, math.hypot(*ref.v_enu_m_s[:2]))
        if math.isnan(reached_s) and math.dist(p_t, state.p_enu_m) < 0.05 and \
                q_angle(q_mul(q_conj(q_t), state.q_enu_flu)) < math.radians(1.0):
            reached_s = t * 1e-6
        wire = through_wire_controls(actuator_controls(out, vehicle.rotor_speed_max_rad_s,
                                                       lockstep=True))
        command = command_from_controls(wire.controls, wire.mode, vehicle, state)
        for _ in range(2):
            state = plant.step(state, command)
        if not pipe.armed:
            break
    return {"armed": pipe.armed, "mode": c.mode, "saturated": pipe.saturated_steps,
            "track_m": track_m, "track_rad": track_rad, "reached_s": reached_s,
            "ref_speed": speed, "lowest_m": state.p_enu_m[2],
            "error_m": math.dist(p_t, state.p_enu_m),
            "error_rad": q_angle(q_mul(q_conj(q_t), state.q_enu_flu))}


@pytest.mark.parametrize(("start", "ned", "rpy", "seconds"), [
    ((-8.0, 5.0, 5.0), (1.0, -2.0, -3.0), (20.0, 0.0, 60.0), 8.0),  # the goto that crashed
    ((0.0, 0.0, 5.0), (30.0, -20.0, -10.0), (0.0, 0.0, -170.0), 14.0),
    ((0.0, 0.0, 5.0), (0.0, 0.0, -5.0), (179.0, 0.0, 0.0), 11.0),  # upside down, 8.8 s
])
def test_a_large_offboard_step_is_flown_at_bounded_speed_and_reached(start, ned, rpy,
                                                                     seconds):
    """Given a hover and an OFFBOARD pose far away in position and attitude, when flown,
    then no rotor saturates, the vehicle stays within centimetres of a reference that moves
    at no more than MPC_VEL_MANUAL (5 m/s), and it reaches the pose (5 cm, 1 deg) and stays
    armed in OFFBOARD."""
    f = fly_offboard(start, PoseTarget.from_euler_deg(ned, *rpy), seconds)
    assert f["armed"] and f["mode"] == Mode.OFFBOARD and f["saturated"] == 0, f
    assert f["track_m"] < 0.1 and f["track_rad"] < math.radians(5.0), f
    assert f["ref_speed"] <= 5.0 + 1e-9, f
    assert f["reached_s"] < seconds - 0.5 and f["error_m"] < 0.01, f
    assert f["error_rad"] < math.radians(0.2), f


def test_hold_at_cruise_speed_brakes_then_holds_where_it_stopped():
    """Given the vehicle flying OFFBOARD at 5 m/s, when HOLD comes, then it brakes within
    the limits (no rotor saturates, tracking within 5 cm: as a step in the reference the
    stop saturated the rotors for 1.7 s and lagged 1.6 m) and comes to rest at the hold
    pose, ahead of where HOLD came, within 1 cm."""
    sc = load_scenario(SCENARIOS / "case1_figure8.toml")
    vehicle = sc.vehicle
    plant = Plant(vehicle, dt_us=1000)
    speeds, tilts = hover_speeds_and_tilts(plant)
    state = plant.initial_state((0.0, 0.0, 5.0), on_ground=False, rotor_speed_rad_s=speeds,
                                tilt_rad=tilts)
    pipe, _ = fcu_pipeline(sc)
    c = pipe.commander
    pipe.on_state(0, state_for_fcu(state), 0)
    assert pipe.arm()[0] == 0
    # 5 m/s north (a velocity set-point, the attitude held level)
    assert c.offboard_position(0.0, position_target(1, 0b0000_1101_1100_0111, (0.0,) * 3,
                                                    (5.0, 0.0, 0.0), (0.0,) * 3, math.nan))[0]
    assert c.offboard_attitude(0.0, attitude_target(
        ATTITUDE_ONLY, q_enu_flu_to_ned_frd(state.q_enu_flu), (0.0,) * 3))[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    track_m, at_hold = 0.0, None
    for k in range(5000):
        t = state.time_us
        if k == 2500:
            at_hold = state.p_enu_m
            assert math.hypot(*state.v_enu_m_s[:2]) > 4.9
            assert c.set_mode(Mode.HOLD, 0.0)[0] == 0
        pipe.on_state(t, state_for_fcu(state), t)
        out = pipe.step(t, 0.002)
        track_m = max(track_m, math.dist(c.last_ref.p_enu_m, state.p_enu_m))
        wire = through_wire_controls(actuator_controls(out, vehicle.rotor_speed_max_rad_s,
                                                       lockstep=True))
        command = command_from_controls(wire.controls, wire.mode, vehicle, state)
        for _ in range(2):
            state = plant.step(state, command)
    assert pipe.armed and c.mode == Mode.HOLD and pipe.saturated_steps == 0
    assert track_m < 0.05
    assert c.modes.brake.hold.p_enu_m[1] > at_hold[1] + 4.0  # it braked from 5 m/s at 3 m/s^2
    assert math.dist(state.p_enu_m, c.modes.brake.hold.p_enu_m) < 0.01
