"""Flights of OFFBOARD steps and HOLD by the FCU's pipeline over the plant, in-process, on a
chosen vehicle file, with the figures the set-point envelope is judged by: the longest run
of control steps in which a commanded tilt moves faster than the servo's rate limit, or a
rotor is commanded at w_max, and the tracking error against the shaped reference."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from common.config import load_scenario, load_vehicle
from common.frames import ned_to_enu, q_ned_frd_to_enu_flu
from common.modes import Mode
from common.quaternion import q_angle, q_conj, q_mul
from gcs.inprocess import (
    actuator_controls,
    command_from_controls,
    fcu_pipeline,
    state_for_fcu,
    through_wire_controls,
)
from gcs.vehicle_link import PoseTarget
from sitl.plant import Plant, hover_speeds_and_tilts

from .conftest import ROOT, SCENARIOS

POSITION_ONLY = 0b0000_1101_1111_1000  # SET_POSITION_TARGET_LOCAL_NED: position and yaw
ATTITUDE_ONLY = 0b0100_0111  # SET_ATTITUDE_TARGET: attitude, no rates, no thrust
DT_S = 0.002  # the control period (500 Hz), two 1 ms plant steps each
VEHICLES = ("hexa_tilted", "hexa_planar")


class Figures:
    """Running figures of a flight (see the module docstring)."""

    def __init__(self, tilt_rate_max: float, speed_max: float) -> None:
        self.tilt_rate_max, self.speed_max = tilt_rate_max, speed_max
        self.last_tilt: tuple[float, ...] | None = None
        self.tilt_run = self.rotor_run = 0
        self.tilt_over_s = self.rotor_over_s = 0.0
        self.tilt_rate_peak = 0.0
        self.track_m = self.track_rad = 0.0

    def add(self, out: Any, ref: Any, state: Any) -> None:
        if self.last_tilt is not None:
            rate = max(abs(math.remainder(a - b, 2.0 * math.pi)) / DT_S
                       for a, b in zip(out.tilt_rad, self.last_tilt, strict=True))
            self.tilt_rate_peak = max(self.tilt_rate_peak, rate)
            self.tilt_run = self.tilt_run + 1 if rate > self.tilt_rate_max else 0
            self.tilt_over_s = max(self.tilt_over_s, self.tilt_run * DT_S)
        self.last_tilt = out.tilt_rad
        at_max = max(out.speed_rad_s) >= self.speed_max * (1.0 - 1e-9)
        self.rotor_run = self.rotor_run + 1 if at_max else 0
        self.rotor_over_s = max(self.rotor_over_s, self.rotor_run * DT_S)
        self.track_m = max(self.track_m, math.dist(ref.p_enu_m, state.p_enu_m))
        self.track_rad = max(self.track_rad,
                             q_angle(q_mul(q_conj(ref.q_enu_flu), state.q_enu_flu)))

    def as_dict(self) -> dict[str, float]:
        return {"tilt_over_s": self.tilt_over_s, "tilt_rate_peak": self.tilt_rate_peak,
                "rotor_over_s": self.rotor_over_s, "track_m": self.track_m,
                "track_deg": math.degrees(self.track_rad)}


def _setup(vehicle_name: str, start_enu_m: tuple[float, float, float]) -> tuple[Any, ...]:
    sc = load_scenario(SCENARIOS / "case1_figure8.toml")
    vehicle = load_vehicle(ROOT / "config" / "vehicles" / f"{vehicle_name}.toml")
    sc = dataclasses.replace(sc, vehicle=vehicle)
    plant = Plant(vehicle, dt_us=1000)
    speeds, tilts = hover_speeds_and_tilts(plant)
    state = plant.initial_state(start_enu_m, on_ground=False, rotor_speed_rad_s=speeds,
                                tilt_rad=tilts)
    pipe, _ = fcu_pipeline(sc)
    pipe.on_state(0, state_for_fcu(state), 0)
    assert pipe.arm()[0] == 0
    return vehicle, plant, state, pipe


def _tick(pipe: Any, plant: Any, vehicle: Any, state: Any, figures: Figures) -> Any:
    t = state.time_us
    pipe.on_state(t, state_for_fcu(state), t)
    out = pipe.step(t, DT_S)
    figures.add(out, pipe.commander.last_ref, state)
    wire = through_wire_controls(actuator_controls(out, vehicle.rotor_speed_max_rad_s,
                                                   lockstep=True))
    command = command_from_controls(wire.controls, wire.mode, vehicle, state)
    for _ in range(2):
        state = plant.step(state, command)
    return state


def fly_pose_step(vehicle_name: str, start_enu_m: tuple[float, float, float],
                  target: PoseTarget, seconds: float) -> dict[str, Any]:
    """Hovering level at `start_enu_m`, armed, OFFBOARD to `target` (a fresh stream)."""
    vehicle, plant, state, pipe = _setup(vehicle_name, start_enu_m)
    c = pipe.commander
    assert c.offboard_position(0.0, 1, POSITION_ONLY, target.p_ned_m, (0.0,) * 3, (0.0,) * 3,
                               0.0)[0]
    assert c.offboard_attitude(0.0, ATTITUDE_ONLY, target.q_ned_frd, (0.0,) * 3)[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    p_t, q_t = ned_to_enu(target.p_ned_m), q_ned_frd_to_enu_flu(target.q_ned_frd)
    figures = Figures(vehicle.tilt_rate_max_rad_s, vehicle.rotor_speed_max_rad_s)
    reached_s = math.nan
    for _ in range(round(seconds / DT_S)):
        state = _tick(pipe, plant, vehicle, state, figures)
        if math.isnan(reached_s) and math.dist(p_t, state.p_enu_m) < 0.05 and \
                q_angle(q_mul(q_conj(q_t), state.q_enu_flu)) < math.radians(1.0):
            reached_s = state.time_us * 1e-6
        if not pipe.armed:
            break
    return {**figures.as_dict(), "armed": pipe.armed, "mode": c.mode, "reached_s": reached_s,
            "error_m": math.dist(p_t, state.p_enu_m),
            "error_deg": math.degrees(q_angle(q_mul(q_conj(q_t), state.q_enu_flu))),
            "rotation_deg_s": c.offboard_limits.yaw_rate_deg_s,
            "acc_xy_m_s2": c.offboard_limits.acc_xy_m_s2}


def fly_hold_at_speed(vehicle_name: str, speed_m_s: float, cruise_s: float,
                      hold_s: float) -> dict[str, Any]:
    """Flying OFFBOARD east to a pose far away, MPC_VEL_MANUAL raised to `speed_m_s`, until
    the vehicle flies at that speed (at most `cruise_s`), then HOLD for `hold_s`: figures
    from the HOLD on."""
    vehicle, plant, state, pipe = _setup(vehicle_name, (0.0, 0.0, 5.0))
    c = pipe.commander
    c.flight = dataclasses.replace(c.flight, sticks=dataclasses.replace(
        c.flight.sticks, speed_xy_m_s=speed_m_s))
    assert c.offboard_position(0.0, 1, POSITION_ONLY, (0.0, 500.0, -5.0), (0.0,) * 3,
                               (0.0,) * 3, math.nan)[0]
    assert c.set_mode(Mode.OFFBOARD, 0.0)[0] == 0
    before = Figures(vehicle.tilt_rate_max_rad_s, vehicle.rotor_speed_max_rad_s)
    for _ in range(round(cruise_s / DT_S)):
        state = _tick(pipe, plant, vehicle, state, before)
        if math.hypot(*c.last_ref.v_enu_m_s[:2]) >= speed_m_s * (1.0 - 1e-6):
            break
    speed = math.hypot(*state.v_enu_m_s[:2])
    assert c.set_mode(Mode.HOLD, 0.0)[0] == 0
    figures = Figures(vehicle.tilt_rate_max_rad_s, vehicle.rotor_speed_max_rad_s)
    for _ in range(round(hold_s / DT_S)):
        state = _tick(pipe, plant, vehicle, state, figures)
        if not pipe.armed:
            break
    hold = c.hold
    return {**figures.as_dict(), "armed": pipe.armed, "mode": c.mode, "speed_at_hold": speed,
            "cruise": before.as_dict(), "error_m": math.dist(state.p_enu_m, hold.p_enu_m),
            "error_deg": math.degrees(q_angle(q_mul(q_conj(hold.q_enu_flu),
                                                   state.q_enu_flu))),
            "acc_xy_m_s2": c._hold_limits.acc_xy_m_s2}
