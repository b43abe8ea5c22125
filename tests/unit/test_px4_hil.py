"""PX4's side of the wire as the plant sees it (sitl/firmware/px4_wire.py,
sitl/firmware/px4_hil.py's pure parts): PX4's hexa X outputs on our rotors, the motor outputs
obeyed, HIL_GPS and HIL_STATE_QUATERNION in PX4's units and frames, the rates and steps chosen."""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import ConfigError, load_scenario, load_vehicle
from common.config.sensors import (
    PROFILE_IMU_RATE_MIN_HZ,
    check_servable,
    resolve_sensor_profile,
    stale_sensors,
)
from common.frames import flu_to_frd
from common.wire.mission_items import PX4_SITL_HOME
from sitl.firmware.px4_hil import physics_step_us, px4_sensor_profile, stale_warning
from sitl.firmware.px4_lockstep import LEARN_WINDOW, Answer, AnswerSchedule, GiveUp
from sitl.firmware.px4_wire import (
    MODE_ARMED,
    command_from_outputs,
    gps_fields,
    motor_order,
    state_fields,
)
from sitl.plant import Plant
from sitl.sensors import GpsModel
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
    g = gps_fields(_state(), PX4_SITL_HOME)
    assert (g.lat, g.lon, g.alt) == (473977420, 85455940, 488000)
    assert (g.fix_type, g.satellites_visible, g.eph, g.epv) == (3, 10, 100, 100)
    assert (g.vel, g.vn, g.ve, g.vd, g.cog) == (0, 0, 0, 0, 65535)
    north = gps_fields(_state(p_enu=(0.0, 10.0, 2.0), v_enu=(0.0, 1.0, -0.5)), PX4_SITL_HOME)
    assert north.lat - 473977420 == round(math.degrees(10.0 / 6_378_137.0) * 1e7)
    assert north.lon == 85455940 and north.alt == 490000
    assert (north.vn, north.ve, north.vd, north.vel, north.cog) == (100, 0, 50, 100, 0)
    east = gps_fields(_state(p_enu=(10.0, 0.0, 0.0), v_enu=(2.0, 0.0, 0.0)), PX4_SITL_HOME)
    assert east.lon > 85455940 and east.lat == 473977420
    assert (east.ve, east.cog) == (200, 9000)


def test_state_quaternion_units_and_frames():
    """Given the body facing east at rest, then HIL_STATE_QUATERNION has yaw +90 deg in NED,
    FRD rates, mm AMSL and the specific force in mG."""
    h = state_fields(_state(w_flu=(0.1, 0.2, 0.3), v_enu=(1.0, 0.0, 0.0)), PX4_SITL_HOME,
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


def test_the_default_profile_is_px4s_noisy_one(scenario):
    """Given no sensor profile, then px4-default: PX4's simulator rates and every sensor
    with white noise (none stale, no warning); given one, then its own; given the exact
    one, then a one-line warning naming the exact sensors."""
    p = px4_sensor_profile(scenario)
    assert p.name == "px4-default" and not p.is_truth
    assert (p.imu.rate_hz, p.mag.rate_hz, p.baro.rate_hz) == (250.0, 100.0, 50.0)
    assert stale_sensors(p) == [] and stale_warning(p) is None
    assert p.imu.gyro.noise_density_rad_s_sqrt_hz == pytest.approx(
        2.0 * 35.0 / 3600.0 / 180.0 * math.pi, rel=1e-4)  # gazebo_imu_plugin.h
    assert p.imu.accel.noise_density_m_s2_sqrt_hz == 4.0e-3
    assert p.mag.noise_gauss == pytest.approx(0.4e-3 * math.sqrt(p.mag.rate_hz))
    assert p.baro.noise_m == pytest.approx(1.0 / (1.17 * 9.80665), rel=0.02)  # 1 Pa
    assert (p.gps.position_noise_m, p.gps.altitude_noise_m) == (0.0028, 0.0056)
    mocap = resolve_sensor_profile("mocap-indoor")
    own = px4_sensor_profile(dataclasses.replace(scenario, sensors=mocap))
    assert own is mocap
    truth = resolve_sensor_profile("truth")
    assert stale_sensors(truth) == ["accel", "gyro", "baro", "mag"]
    line = stale_warning(truth)
    assert line is not None and "\n" not in line and "stale" in line


def test_the_home_field_is_px4s_table_at_its_home():
    """Given px4-default's earth field, then declination 3.33 deg, inclination 63.15 deg
    and strength 0.482 gauss: PX4's WMM table bilinearly interpolated at its SITL home
    (the corners of 40-50 N, 0-10 E in geo_magnetic_tables.hpp)."""
    n, e, d = resolve_sensor_profile("px4-default").mag.field_ned_gauss
    fy, fx = (PX4_SITL_HOME.lat_deg - 40.0) / 10.0, PX4_SITL_HOME.lon_deg / 10.0

    def table(v00: float, v01: float, v10: float, v11: float) -> float:
        return (1 - fy) * ((1 - fx) * v00 + fx * v01) + fy * ((1 - fx) * v10 + fx * v11)

    decl, incl = table(227, 587, 168, 670) * 1e-4, table(9581, 9747, 11387, 11494) * 1e-4
    strength = table(4514, 4595, 4861, 4913) * 1e-4
    assert math.atan2(e, n) == pytest.approx(decl, abs=2e-3)
    assert math.atan2(d, math.hypot(n, e)) == pytest.approx(incl, abs=2e-3)
    assert math.sqrt(n * n + e * e + d * d) == pytest.approx(strength, abs=5e-4)


def test_gps_noise_and_accuracy_as_declared():
    """Given px4-default's GNSS, then each fix is white noise of the declared sigmas around
    the truth (seeded: the same seed, the same fixes) and reports eph 100 cm, epv 100 cm,
    10 satellites, 3D (Gazebo classic's gps plugin, as PX4 meets it through HIL_GPS)."""
    cfg = resolve_sensor_profile("px4-default").gps
    fixes = [GpsModel(cfg, 3).sample((1.0, 2.0, 3.0), (0.0, 0.0, 0.0)) for _ in range(1)]
    m = GpsModel(cfg, 3)
    got = np.array([sum(m.sample((1.0, 2.0, 3.0), (0.0, 0.0, 0.0)), ()) for _ in range(4000)])
    assert got[0].tolist() == list(sum(fixes[0], ()))
    assert got.mean(axis=0) == pytest.approx((1.0, 2.0, 3.0, 0.0, 0.0, 0.0), abs=0.002)
    assert got.std(axis=0) == pytest.approx((0.0028, 0.0028, 0.0056, 0.0126, 0.0126, 0.0253),
                                          rel=0.05)
    g = gps_fields(_state(), PX4_SITL_HOME, cfg)
    assert (g.fix_type, g.eph, g.epv, g.satellites_visible) == (3, 100, 100, 10)


def test_px4s_imu_floor_is_not_the_fcus():
    """Given a 250 Hz or 100 Hz IMU, then the loader and PX4's link take it, this project's
    FCU link (500 Hz at least) refuses it."""
    p = resolve_sensor_profile("px4-default")
    check_servable(p, 1000, 4000, imu_rate_min_hz=PROFILE_IMU_RATE_MIN_HZ)
    slow = dataclasses.replace(p, imu=dataclasses.replace(p.imu, rate_hz=100.0))
    check_servable(slow, 1000, 10000, imu_rate_min_hz=PROFILE_IMU_RATE_MIN_HZ)
    with pytest.raises(ConfigError, match=r"imu\.rate_hz = 250 is below 500 Hz"):
        check_servable(p, 1000, 4000)


def test_the_schedule_learns_px4s_answer_period():
    """Given 1 kHz samples and answers every 4 samples, then the period is learned once two
    windows of 8 intervals have the same longest one; the plant waits only at the samples
    where an answer is due; an answer that does not come moves the due sample a period on,
    and the interval of the answer after it (8) becomes the longest; stale and second
    answers are told apart."""
    s = AnswerSchedule(1000)
    assert s.accept(300_000, 300_000) is Answer.ON_TIME and not s.learned
    assert s.accept(302_000, 303_000) is Answer.LATE and not s.learned  # paced: ran past
    for n in range(1, 2 * LEARN_WINDOW):
        assert s.accept(302_000 + 4000 * n, 302_000 + 4000 * n) is Answer.ON_TIME
        assert s.learned == (n == 2 * LEARN_WINDOW - 1)
    last = 302_000 + 4000 * (2 * LEARN_WINDOW - 1)
    assert (s.period, s.longest, s.due_us) == (4, 4, last + 4000)
    assert next(t for t in range(last, last + 12_001, 1000) if s.waits_at(t)) == last + 4000
    assert not s.waits_at(last + 3000)
    assert s.accept(last, last + 4000) is Answer.EXTRA
    assert s.accept(last - 4000, last + 4000) is Answer.STALE
    s.skip()  # the answer due at last + 4 ms never came: learned again, on the wall clock
    assert not s.learned and s.due_us is None and s.last_us == last
    assert s.accept(last + 8000, last + 8000) is Answer.ON_TIME and not s.learned
    for n in range(1, 2 * LEARN_WINDOW + 1):
        assert s.accept(last + 8000 + 4000 * n, last + 8000 + 4000 * n) is Answer.ON_TIME
    assert (s.period, s.longest) == (4, 4)  # the 8 of the stall is not the cadence
    assert s.intervals == {2: 1, 4: 4 * LEARN_WINDOW - 1, 8: 1}
    s.reset()
    assert not s.learned and s.due_us is None and s.longest is None


def test_the_schedule_waits_at_the_longest_of_varying_intervals():
    """Given a 1 kHz IMU and PX4's rate-limited answers every 3 or 2 samples, then the
    schedule learns the longest (3) and waits 3 samples after each answer; an answer after
    2 samples comes before that and applies from the step after it arrives (LATE once the
    plant ran past it); an answer that does not come makes it learn again."""
    s = AnswerSchedule(1000)
    t = 0
    for k in range(2 * LEARN_WINDOW + 1):
        t += 3000 if k % 2 else 2000
        s.accept(t, t)
    assert (s.period, s.longest, s.due_us) == (3, 3, t + 3000)
    assert s.accept(t + 2000, t + 3000) is Answer.LATE and s.due_us == t + 5000
    s.skip()  # a longer gap than learned: the cadence is learned again
    assert not s.learned and s.accept(t + 6000, t + 6000) is Answer.ON_TIME


def test_a_cadence_learned_too_short_grows_one_sample_at_a_time():
    """Given PX4's start-up (an answer every sample, learned as a cadence of 1) and then its
    settled cadence of 4 samples, then each `step_past` moves the wait one sample on, the
    answer that needed those samples lengthens the interval waited for to 4, and a slow
    answer at the sample due (stamped before the latest sent) leaves it as it was."""
    s = AnswerSchedule(2000)
    t = 0
    for _ in range(2 * LEARN_WINDOW + 1):
        t += 2000
        s.accept(t, t)
    assert (s.longest, s.due_us) == (1, t + 2000)
    for k in range(1, 4):  # the answer due does not come: one sample on each time
        assert s.waits_at(t + 2000 * k)
        s.step_past()
        assert s.due_us == t + 2000 * (k + 1) and not s.waits_at(t + 2000 * k)
    assert s.accept(t + 8000, t + 8000) is Answer.ON_TIME
    assert (s.longest, s.due_us) == (4, t + 16_000)
    s.step_past()  # slow, not longer: its answer is stamped at the sample it was due at
    assert s.accept(t + 16_000, t + 18_000) is Answer.LATE
    assert (s.longest, s.due_us) == (4, t + 24_000)


def test_the_wait_for_an_answer_steps_past_then_gives_up_on_the_wall_clock():
    """Given a learned cadence of 1 sample and no answer at the sample due, then the schedule
    says wait until the grace has passed, then step one sample past it, again each grace,
    and give up (learned again, and recorded) once the timeout has passed since the wait
    began; an answer that comes ends the wait, and the next one starts afresh. Each step
    past is recorded: the sample left, when its grace began and ended."""
    from sitl.firmware.px4_lockstep import StepPast, Wait
    s = AnswerSchedule(1000)
    for k in range(1, 2 * LEARN_WINDOW + 2):
        s.accept(1000 * k, 1000 * k)
    t = 1000 * (2 * LEARN_WINDOW + 1)
    assert s.wait_at(t, 10.0, 0.05, 1.0) == (Wait.STEP, 10.0)  # answered: step
    sent = t + 1000
    assert s.wait_at(sent, 10.0, 0.05, 1.0) == (Wait.WAIT, 10.05)
    assert s.wait_at(sent, 10.04, 0.05, 1.0) == (Wait.WAIT, 10.05)
    assert s.wait_at(sent, 10.05, 0.05, 1.0)[0] is Wait.STEP_PAST and s.due_us == sent + 1000
    assert s.wait_at(sent, 10.06, 0.05, 1.0)[0] is Wait.STEP  # not due at `sent` any more
    sent += 1000
    assert s.wait_at(sent, 10.07, 0.05, 1.0) == (Wait.WAIT, pytest.approx(10.10))  # from 10.05
    assert s.accept(sent, sent) is Answer.ON_TIME and s.longest == 2
    sent += 2000
    assert s.wait_at(sent, 11.0, 0.05, 1.0) == (Wait.WAIT, 11.05)  # a new wait
    expected = [StepPast(t + 1000, 10.0, 10.05)]
    for k in range(1, 17):
        wait, _ = s.wait_at(sent, 11.0 + 0.06 * k, 0.05, 1.0)
        assert wait is Wait.STEP_PAST
        expected.append(StepPast(sent, 11.0 + 0.06 * (k - 1), 11.0 + 0.06 * k))
        sent = s.due_us
    assert list(s.step_pasts) == expected
    assert s.stats()["answer_step_pasts"][0] == {"sample_us": t + 1000, "began_s": 10.0,
                                                 "waited_s": 0.05}
    assert s.give_ups == deque()
    assert s.wait_at(sent, 12.0, 0.05, 1.0)[0] is Wait.GIVE_UP and not s.learned
    # recorded: the sample waited at, the answer accepted before (the next was owed), the
    # wall times the wait began and ended
    assert list(s.give_ups) == [GiveUp(sent, t + 2000, 11.0, 12.0)]
    assert s.stats()["answer_give_ups"] == [{"sample_us": sent, "answered_us": t + 2000,
                                             "began_s": 11.0, "waited_s": 1.0}]


def test_an_answer_that_was_only_slow_doubles_the_grace():
    """Given a learned cadence of 1 sample and an answer that comes after the plant stepped
    past it, stamped at the sample it was due at (slow, not longer), then it is late, the
    cadence stays, and the grace doubles, up to MAX_GRACE_SCALE times and half the
    timeout; an answer that needed the sample stepped to changes no grace."""
    from sitl.firmware.px4_lockstep import MAX_GRACE_SCALE, Wait
    s = AnswerSchedule(1000)
    for k in range(1, 2 * LEARN_WINDOW + 2):
        s.accept(1000 * k, 1000 * k)
    sent = 1000 * (2 * LEARN_WINDOW + 2)
    assert s.wait_at(sent, 0.0, 0.05, 1.0) == (Wait.WAIT, 0.05)
    assert s.wait_at(sent, 0.05, 0.05, 1.0)[0] is Wait.STEP_PAST
    assert s.accept(sent, sent + 1000) is Answer.LATE  # the answer due, after the step
    assert (s.longest, s.grace_scale, s.slow_answers, s.slow_steps) == (1, 2, 1, 1)
    sent = s.due_us
    assert s.wait_at(sent, 1.0, 0.05, 1.0) == (Wait.WAIT, pytest.approx(1.1))
    assert s.wait_at(sent, 1.1, 0.05, 1.0)[0] is Wait.STEP_PAST
    assert s.accept(sent + 1000, sent + 1000) is Answer.ON_TIME  # it needed that sample
    assert (s.longest, s.grace_scale, s.slow_answers) == (2, 2, 1)
    for k in range(6):
        sent = s.due_us
        t = 10.0 + k
        wait, until = s.wait_at(sent, t, 0.05, 1.0)
        assert wait is Wait.WAIT
        assert until == pytest.approx(t + min(0.05 * s.grace_scale, 0.5))
        assert s.wait_at(sent, until + 1e-9, 0.05, 1.0)[0] is Wait.STEP_PAST
        assert s.accept(sent, sent + 1000) is Answer.LATE
    assert s.grace_scale == MAX_GRACE_SCALE and s.slow_answers == s.slow_waits == 7
