"""The FCU's pipeline flying the plant in-process from a hover, with the figures the
set-point tests judge (tracking, the actuator monitor's longest rate-limited run, its
reports); a random OFFBOARD step. Used by tests/closed_loop/test_shaped_setpoints.py and
benchmarks/offboard_steps.py."""

from __future__ import annotations

import dataclasses
import math
import random
from pathlib import Path

from common.config.scenario import load_scenario, load_vehicle
from common.quaternion import Quat, Vec3, q_angle, q_conj, q_exp, q_mul
from gcs.run.inprocess import command_for_plant, fcu_pipeline, state_for_fcu
from sitl.plant import Plant, hover_speeds_and_tilts

ROOT = Path(__file__).resolve().parents[1]

VEHICLES = ["hexa_tilted", "hexa_planar"]
LIMIT_S = 0.1  # COM_ACT_RATE_T
POSITION_ONLY = 0b0000_1101_1111_1000  # SET_POSITION_TARGET_LOCAL_NED: position and yaw
VELOCITY_ONLY = 0b0000_1101_1100_0111  # ... velocity and yaw
ATTITUDE_ONLY = 0b0100_0111  # SET_ATTITUDE_TARGET: attitude, no rates, no thrust


class Flight:
    """The pipeline flying the plant from a hover at `start_enu_m`, armed; `step` runs one
    control period and keeps the figures."""

    def __init__(self, vehicle_name: str, start_enu_m: Vec3) -> None:
        sc = dataclasses.replace(
            load_scenario(ROOT / "config" / "scenarios" / "case1_figure8.toml"),
            vehicle=load_vehicle(ROOT / "config" / "vehicles" / f"{vehicle_name}.toml"))
        self.vehicle = sc.vehicle
        self.plant = Plant(self.vehicle, dt_us=1000)
        speeds, tilts = hover_speeds_and_tilts(self.plant)
        state = self.plant.initial_state(start_enu_m, on_ground=False,
                                         rotor_speed_rad_s=speeds, tilt_rad=tilts)
        self.state = state
        self.pipe, _ = fcu_pipeline(sc)
        self.pipe.on_state(0, state_for_fcu(self.state), 0)
        assert self.pipe.arm()[0] == 0
        self.track_m = self.track_rad = self.limited_s = 0.0

    def step(self) -> None:
        state, pipe = self.state, self.pipe
        t = state.time_us
        pipe.on_state(t, state_for_fcu(state), t)
        out = pipe.step(t, 0.002)
        ref = pipe.commander.last_ref
        assert ref is not None, "a flying pipeline has a reference"
        self.track_m = max(self.track_m, math.dist(ref.p_enu_m, state.p_enu_m))
        self.track_rad = max(self.track_rad,
                             q_angle(q_mul(q_conj(ref.q_enu_flu), state.q_enu_flu)))
        self.limited_s = max(self.limited_s, *pipe.actuators.limited_s)
        command = command_for_plant(out, self.vehicle, state)
        for _ in range(2):
            state = self.plant.step(state, command)
        self.state = state

    def reports(self) -> list[str]:
        return [e.text for e in self.pipe.commander.events
                if "rate-limited" in e.text or "speed limit" in e.text]


def random_step(rng: random.Random) -> tuple[Vec3, Quat]:
    """A random OFFBOARD step from a hover: up to 20 m away (and 0..10 m up or down), turned
    0..180 deg about a random axis."""
    axis = [rng.gauss(0.0, 1.0) for _ in range(3)]
    n = math.sqrt(sum(a * a for a in axis))
    angle = math.radians(rng.uniform(0.0, 180.0))
    p = (rng.uniform(-20.0, 20.0), rng.uniform(-20.0, 20.0), 15.0 + rng.uniform(-10.0, 10.0))
    return p, q_exp((angle * axis[0] / n, angle * axis[1] / n, angle * axis[2] / n))
