"""PX4's side of the wire as the plant sees it (sitl/px4_wire.py, sitl/px4_hil.py's pure
parts): PX4's hexa X outputs on our rotors, the motor outputs obeyed, HIL_GPS and
HIL_STATE_QUATERNION in PX4's units and frames, the rates and steps chosen."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from common.config import ConfigError, load_scenario, load_vehicle
from common.frames import flu_to_frd
from sitl.plant import Plant
from sitl.px4_hil import physics_step_us, px4_sensor_profile
from sitl.px4_wire import (
    MODE_ARMED,
    PX4_HOME,
    command_from_outputs,
    gps_fields,
    motor_order,
    state_fields,
)
from tests.px4_side import HEXA_X

ROOT = Path(__file__).resolve().parents[2]
PX4_HEXA = ROOT / "config" / "scenarios" / "px4_hexa.toml"
VEHICLES = ROOT / "config" / "vehicles"


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(PX4_HEXA)


def _sign(v: float, eps: float = 1e-9) -> int:
    return 0 if abs(v) < eps else (1 if v > 0 else -1)


def test_motor_order_is_pinned(scenario):
    """Given PX4's hexa X on config/scenarios/px4_hexa.toml, then MAIN1..6 drive rotors 4,
    1, 0, 3, 5, 2 (right, left, front-left, rear-right, front-right, rear-left)."""
    assert motor_order(scenario.vehicle) == (4, 1, 0, 3, 5, 2)


@pytest.mark.parametrize("k", range(6))
def test_each_output_torques_as_px4_allocates(scenario, k):
    """Given one PX4 output spinning alone, then its torque in FRD has the roll sign of
    -CA_ROTOR_PY, the pitch sign of +CA_ROTOR_PX and the yaw sign of CA_ROTOR_KM (6001)."""
    plant = Plant(scenario.vehicle)
    order = motor_order(scenario.vehicle)
    speeds = [0.0] * 6
    speeds[order[k]] = 800.0
    force, torque_flu = plant.rotor_wrench(speeds, [0.0] * 6)
    roll, pitch, yaw = flu_to_frd(torque_flu)
    px, py, km = HEXA_X[k]
    assert force[2] > 0  # thrust up
    assert _sign(roll, 1e-6) == -_sign(py)
    assert _sign(pitch, 1e-6) == _sign(px)
    assert _sign(yaw) == km


def test_all_outputs_equal_give_no_torque(scenario):
    """Given equal outputs on all six, then the plant feels thrust and no torque."""
    plant = Plant(scenario.vehicle)
    cmd = command_from_outputs((0.6,) * 6 + (0.0,) * 10, MODE_ARMED | 1,
                               motor_order(scenario.vehicle), 1700.0).command
    _, torque = plant.rotor_wrench(cmd.rotor_speed_rad_s, cmd.tilt_rad)
    assert max(abs(t) for t in torque) < 1e-9


def test_vehicles_px4_cannot_fly_are_refused():
    """Given the planar hexa (spins mirrored) or the tilted one, then ConfigError says why."""
    with pytest.raises(ConfigError, match=r"rotor 4 spins counter-clockwise, PX4's hexa X "
                       r"motor 1 there spins clockwise .*px4_hexa.toml"):
        motor_order(load_vehicle(VEHICLES / "hexa_planar.toml"))
    with pytest.raises(ConfigError, match="tilted out of the body plane"):
        motor_order(load_vehicle(VEHICLES / "hexa_tilted.toml"))


def test_outputs_to_rotor_speeds():
    """Given PX4's motor outputs, then rotor order[k] turns at clamp(u, 0, 1) w_max when
    armed, nothing when disarmed, a non-finite output stops its rotor (counted), tilts 0."""
    order = (4, 1, 0, 3, 5, 2)
    controls = (0.5, 1.5, -0.2, math.nan, 0.25, math.inf) + (0.7,) * 10
    c = command_from_outputs(controls, MODE_ARMED | 1, order, 1000.0)
    speeds = c.command.rotor_speed_rad_s
    assert speeds == (0.0, 1000.0, 0.0, 0.0, 500.0, 250.0)
    assert c.nonfinite == 2
    assert c.command.tilt_rad == (0.0,) * 6
    off = command_from_outputs(controls, 1, order, 1000.0)
    assert off.command.rotor_speed_rad_s == (0.0,) * 6


def _state(p_enu=(0.0, 0.0, 0.0), v_enu=(0.0, 0.0, 0.0), q=(1.0, 0.0, 0.0, 0.0),
           w_flu=(0.0, 0.0, 0.0)):
    from sitl.plant import PlantState

    return PlantState(1_000_000, p_enu, v_enu, q, w_flu, (0.0,) * 6, (0.0,) * 6, True)


def test_gps_units_and_frames():
    """Given the state at home, moving or displaced, then HIL_GPS has degE7, mm AMSL, cm/s
    NED and the course in cdeg as PX4 reads them."""
    g = gps_fields(_state(), PX4_HOME)
    assert (g.lat, g.lon, g.alt) == (473977420, 85455940, 488000)
    assert (g.fix_type, g.satellites_visible, g.eph, g.epv) == (3, 10, 100, 100)
    assert (g.vel, g.vn, g.ve, g.vd, g.cog) == (0, 0, 0, 0, 65535)
    north = gps_fields(_state(p_enu=(0.0, 10.0, 2.0), v_enu=(0.0, 1.0, -0.5)), PX4_HOME)
    assert north.lat - 473977420 == round(math.degrees(10.0 / 6_378_137.0) * 1e7)
    assert north.lon == 85455940 and north.alt == 490000
    assert (north.vn, north.ve, north.vd, north.vel, north.cog) == (100, 0, 50, 100, 0)
    east = gps_fields(_state(p_enu=(10.0, 0.0, 0.0), v_enu=(2.0, 0.0, 0.0)), PX4_HOME)
    assert east.lon > 85455940 and east.lat == 473977420
    assert (east.ve, east.cog) == (200, 9000)


def test_state_quaternion_units_and_frames():
    """Given the body facing east at rest, then HIL_STATE_QUATERNION has yaw +90 deg in NED,
    FRD rates, mm AMSL and the specific force in mG."""
    h = state_fields(_state(w_flu=(0.1, 0.2, 0.3), v_enu=(1.0, 0.0, 0.0)), PX4_HOME,
                     (0.0, 0.0, 9.80665))
    w, x, y, z = h.attitude_quaternion
    assert w == pytest.approx(math.sqrt(0.5)) and z == pytest.approx(math.sqrt(0.5))
    assert x == pytest.approx(0.0) and y == pytest.approx(0.0)
    assert (h.rollspeed, h.pitchspeed, h.yawspeed) == (0.1, -0.2, -0.3)
    assert (h.vx, h.vy, h.vz) == (0, 100, 0)
    assert (h.xacc, h.yacc, h.zacc) == (0, 0, -1000)
    assert (h.lat, h.lon, h.alt) == (473977420, 85455940, 488000)


@pytest.mark.parametrize(("imu_us", "physics_hz", "dt"), [
    (4000, 1000, 1000), (4000, 1200, 800), (1000, 1000, 1000), (3000, 2000, 500),
    (8000, 100, 8000)])
def test_physics_step_divides_the_imu_period(imu_us, physics_hz, dt):
    """Given an IMU period and the scenario's physics rate, then the step divides the period
    and is not longer than the scenario's."""
    assert physics_step_us(imu_us, physics_hz) == dt


def test_rates_from_the_profile_else_px4s(scenario):
    """Given no sensor profile, then PX4's simulator rates; given one, then its own."""
    p = px4_sensor_profile(scenario)
    assert (p.imu.rate_hz, p.mag.rate_hz, p.baro.rate_hz) == (250.0, 100.0, 50.0)
    assert p.is_truth
    from common.sensors_config import resolve_sensor_profile

    mocap = resolve_sensor_profile("mocap-indoor")
    own = px4_sensor_profile(dataclasses.replace(scenario, sensors=mocap))
    assert own is mocap
