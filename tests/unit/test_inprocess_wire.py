"""The in-process runner's shortcuts through the simulator link give each side what the link
gives it, to the bit: `imu_for_fcu` and `pose_for_fcu` against the full round trip
(`through_wire_*`, then `fcu.edge.sim_bridge`'s conversions), `command_for_plant` against
HIL_ACTUATOR_CONTROLS's (`actuator_controls`, the wire, `command_from_controls`), and the
plant's accelerometer kernel against the rotor wrench and disturbance it sums."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import load_scenario
from common.vehicle_constants import N_ROTORS
from common.wire.simlink import (
    HilSensor,
    Odometry,
    pose_covariance,
    through_wire_controls,
    through_wire_hil_sensor,
    through_wire_odometry,
)
from fcu.edge.sim_bridge import actuator_controls, imu_from_hil_sensor, pose_from_odometry
from fcu.pipeline import StepOutput
from gcs.run.inprocess import command_for_plant, imu_for_fcu, pose_for_fcu
from sitl.plant import scenario_plant
from sitl.plant_kernels import rotor_wrench_kernel, with_disturbance
from sitl.world import command_from_controls

NAN = math.nan
ROOT = Path(__file__).resolve().parents[2]


def _bits(values: tuple[float, ...]) -> bytes:
    """The float64 bits of a tuple of numbers."""
    return b"".join(struct.pack("<d", v) for v in values)


def _hil(rng: np.random.Generator, t: int) -> HilSensor:
    v = [float(x) for x in rng.normal(0.0, 3.0, 9)]
    return HilSensor(t, (v[0], v[1], v[2]), (v[3], v[4], v[5]), (v[6], v[7], v[8]),
                     1000.0 + v[0], v[1], 15.0, 0x3F)


def test_imu_for_fcu_is_the_wire_round_trip_to_the_bit():
    rng = np.random.default_rng(3)
    cases = [_hil(rng, 1000 * k) for k in range(500)]
    cases.append(HilSensor(7, (NAN, 1e-40, -0.0), (math.inf, -1e30, 3.0), (NAN,) * 3,
                           NAN, NAN, 15.0, 0))
    for h in cases:
        want = imu_from_hil_sensor(through_wire_hil_sensor(h))
        got = imu_for_fcu(h)
        assert got.t_us == want.t_us
        assert _bits(got.omega_flu_rad_s) == _bits(want.omega_flu_rad_s)
        assert _bits(got.f_flu_m_s2) == _bits(want.f_flu_m_s2)
    with pytest.raises(OverflowError):
        imu_for_fcu(HilSensor(1, (1e39, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3, 0.0, 0.0, 0.0, 0))


def _odometry(rng: np.random.Generator, t: int) -> Odometry:
    p = [float(x) for x in rng.normal(0.0, 5.0, 3)]
    n = rng.normal(0.0, 1.0, 4)
    q = [float(x) for x in n / np.linalg.norm(n)]
    return Odometry(t, (p[0], p[1], p[2]), (q[0], q[1], q[2], q[3]), (NAN,) * 3, (NAN,) * 3, 6,
                    pose_covariance(float(rng.uniform(1e-9, 1e-3)),
                                    float(rng.uniform(1e-9, 1e-3))))


def test_pose_for_fcu_is_the_wire_round_trip_to_the_bit():
    rng = np.random.default_rng(5)
    cases = [_odometry(rng, 5000 * k) for k in range(500)]
    base = cases[0]
    cases += [base._replace(p_ned_m=(NAN, 0.0, 0.0)),
              base._replace(q_ned_frd=(1.0, 0.0, 0.0, NAN)),
              base._replace(q_ned_frd=(1.1, 0.0, 0.0, 0.0)),  # not a unit quaternion
              base._replace(p_ned_m=(0.0, 2e6, 0.0)),  # absurdly far
              base._replace(pose_covariance=pose_covariance(NAN, -1.0)),
              base._replace(pose_covariance=pose_covariance(0.0, math.inf)),
              base._replace(pose_covariance=pose_covariance(1e-50, 1e-50))]
    refused = 0
    for o in cases:
        want = pose_from_odometry(through_wire_odometry(o))
        got = pose_for_fcu(o)
        if want is None:
            refused += 1
            assert got is None
            continue
        assert got is not None
        assert got.capture_us == want.capture_us
        assert _bits((*got.p_enu_m, *got.q_enu_flu, got.pos_var_m2, got.att_var_rad2)) == \
            _bits((*want.p_enu_m, *want.q_enu_flu, want.pos_var_m2, want.att_var_rad2))
    assert refused == 4


def test_command_for_plant_is_the_wire_round_trip_to_the_bit():
    """Armed and disarmed, with speeds and tilts that are not finite (zero speed, the
    current tilt), tiny, negative, beyond the rotor's limit: the plant obeys the same
    command either way."""
    scenario = load_scenario(ROOT / "config/scenarios/case1_figure8.toml")
    vehicle, plant = scenario.vehicle, scenario_plant(scenario, 1000)
    w_max = vehicle.rotor_speed_max_rad_s
    rng = np.random.default_rng(13)
    state = plant.initial_state((0.0, 0.0, 1.0), on_ground=False,
                                tilt_rad=tuple(float(x) for x in rng.uniform(-1, 1, N_ROTORS)))
    odd = (NAN, math.inf, -math.inf, 1e-45, -0.0, 1.3 * w_max)
    cases = []
    for k in range(300):
        speeds = [float(x) for x in rng.uniform(0.0, w_max, N_ROTORS)]
        tilts = [float(x) for x in rng.uniform(-4.0, 4.0, N_ROTORS)]
        if k % 3 == 0:
            speeds[k % N_ROTORS] = odd[k % len(odd)]
            tilts[(k + 1) % N_ROTORS] = odd[(k + 2) % len(odd)]
        cases.append(StepOutput(k, tuple(speeds), tuple(tilts), k % 7 != 0, None))
    for out in cases:
        wire = through_wire_controls(actuator_controls(out, w_max, True))
        want = command_from_controls(wire.controls, wire.mode, vehicle, state)
        got = command_for_plant(out, vehicle, state)
        assert _bits(got.rotor_speed_rad_s) == _bits(want.rotor_speed_rad_s)
        assert _bits(got.tilt_rad) == _bits(want.tilt_rad)
    # what the plant makes of values that are not finite (`obeyed_command`)
    got = command_for_plant(StepOutput(0, (NAN, math.inf) + (100.0,) * (N_ROTORS - 2),
                                       (-math.inf,) + (0.5,) * (N_ROTORS - 1), True, None),
                            vehicle, state)
    assert got.rotor_speed_rad_s[:3] == (0.0, 0.0, pytest.approx(100.0, rel=1e-6))
    assert got.tilt_rad[:2] == (state.tilt_rad[0], 0.5)


def test_the_accelerometer_kernel_is_the_wrench_and_disturbance_per_mass():
    """`Plant.specific_force_flu` in flight (one kernel) against the rotor wrench and the
    disturbance it adds, summed as before, during the scenario's impulse and outside it."""
    scenario = load_scenario(ROOT / "config/scenarios/case2_impulse.toml")
    plant = scenario_plant(scenario, 1000)
    plant.disturbance = plant.disturbance.from_time(0.0)
    assert plant.disturbance.active
    rng = np.random.default_rng(11)
    base = plant.initial_state((0.0, 0.0, 1.0), on_ground=False)
    differs = 0
    for k in range(400):
        speeds = tuple(float(x) for x in rng.uniform(0.0, 900.0, N_ROTORS))
        tilts = tuple(float(x) for x in rng.uniform(-3.0, 3.0, N_ROTORS))
        s = base._replace(time_us=k * 60_000, rotor_speed_rad_s=speeds, tilt_rad=tilts)
        r = rotor_wrench_kernel(plant.params, np.array(speeds), np.array(tilts))
        w = with_disturbance(plant.params, plant.disturbance.table, r, s.time_us * 1e-6)
        want = (w[0] / plant.mass, w[1] / plant.mass, w[2] / plant.mass)
        assert _bits(plant.specific_force_flu(s)) == _bits(want)
        differs += w[:3] != r[:3]
    assert 0 < differs < 400  # the disturbance acted on some samples, not all
    with pytest.raises(ValueError):
        plant.specific_force_flu(base._replace(tilt_rad=(0.0,) * (N_ROTORS - 1)))
