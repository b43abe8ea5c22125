"""The commander's landing (fcu/commander.py): the set-point sinks below the planned end of
the descent until the land detector sees the vehicle held up and still, then disarms; a
vehicle still in the air is never taken for landed."""

from __future__ import annotations

from pathlib import Path

from common.config import load_gains, load_vehicle
from common.modes import Mode
from common.outcome import CRASH
from fcu.commander import (
    LANDED_STILL_S,
    MAV_RESULT_DENIED,
    TOUCHDOWN_DEPTH_M,
    pose_ref,
)
from fcu.failsafe import FailsafeSettings
from fcu.mission import MissionLimits
from fcu.pipeline import Pipeline
from fcu.tracker import VehicleState

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
    """Given LAND from 2 m at 0.5 m/s, when the planned descent has ended (the vehicle held
    0.3 m up, e.g. by an error), then the set-point keeps sinking at the land speed, at most
    TOUCHDOWN_DEPTH_M below the plan's end, and nothing disarms a vehicle that moves."""
    pipe = _landing_pipeline(2.0)
    c = pipe.commander
    t = 0
    while c.touchdown is None:
        t += 2000
        pipe.on_state(t, _state(0.3, -0.3), t)  # in the air, still descending
        pipe.step(t)
        assert t < 20_000_000
    end = c.touchdown
    samples = []
    for _ in range(2000):  # 4 s
        t += 2000
        pipe.on_state(t, _state(0.3, -0.3), t)
        out = pipe.step(t)
        samples.append(c.last_ref.p_enu_m[2])
        assert out.armed  # moving: not landed
    dt = 0.1
    assert abs(samples[49] - (end.p_enu_m[2] - 0.5 * dt)) < 1e-9  # 0.1 s after: 5 cm lower
    assert min(samples) == end.p_enu_m[2] - TOUCHDOWN_DEPTH_M


def _to_touchdown(pipe: Pipeline, z: float) -> int:
    """Step through the planned descent with the vehicle held at height z; the time the
    touchdown phase starts."""
    t = 0
    while pipe.commander.touchdown is None:
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
    assert start + LANDED_STILL_S * 1e6 <= t <= start + LANDED_STILL_S * 1e6 + 4000
    texts = [e.text for e in pipe.events]
    assert "landed: disarmed" in texts and "disarmed in the air" not in texts


def test_a_set_point_just_below_is_not_support():
    """Given the touchdown phase and a still vehicle with zero lift, when the set-point is
    only 5 cm below it (less than TOUCHDOWN_BLOCKED_M) and the vehicle is above ground level,
    then the land detector does not call it landed."""
    pipe = _landing_pipeline(0.3)
    start = _to_touchdown(pipe, 0.3)
    c = pipe.commander
    c.last_ref = pose_ref((1.0, 2.0, 0.25), c.touchdown.q_enu_flu)
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
        assert pipe.commander.disarm()[0] == MAV_RESULT_DENIED
        pipe.commander.disarm(force=True)
        assert any(e.kind == CRASH for e in pipe.events)


def test_saturation_is_monitored_in_the_step():
    """Given an offboard target 30 m away (the rotors saturate) and COM_SAT_T = 0.2 s, when
    the pipeline steps for 0.5 s, then the saturation is counted and reported."""
    vehicle = load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml")
    pipe = Pipeline(vehicle, load_gains(ROOT / "config/gains/pid_eq30.toml"), 500,
                    failsafes=FailsafeSettings(saturation_s=0.2, divergence_m=1000.0))
    pipe.on_state(0, _state(5.0), 0)
    pipe.arm()
    c = pipe.commander
    assert c.offboard_position(0.0, 1, 0, (30.0, 0.0, -5.0), (0.0, 0.0, 0.0),
                               (0.0, 0.0, 0.0), 0.0)[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    for t in range(0, 500_000, 2000):
        pipe.on_state(t, _state(5.0), t)
        pipe.step(t, 0.002)
    assert pipe.saturated_steps > 100 and pipe.failsafe == "rotor saturation"
    assert any(e.text.startswith("rotors saturated") for e in pipe.events)
