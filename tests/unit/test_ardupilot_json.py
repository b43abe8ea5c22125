"""ArduPilot's JSON physics interface (sitl.firmware.ardupilot_json): servo packets, the JSON answer
and its frames, stepping on new frame counts only, restarts, ArduPilot's clock, the hexa X
motor map, and the server on loopback against a scripted ArduPilot side."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re
import socket
import struct
import threading
from pathlib import Path

import numpy as np
import pytest

from common.config.scenario import ActuatorFault, ConfigError, load_scenario, load_vehicle
from common.links import LinkError, free_port
from common.logs.ulog import read_topic
from common.quaternion import q_exp, q_mul
from sitl.firmware.ardupilot_json import (
    MAGIC_16,
    MAGIC_32,
    JsonPhysics,
    Server,
    ServoPacket,
    motor_map,
    parse_servo_packet,
    rotor_speeds,
    state_json,
    step_us,
)
from sitl.plant import hover_speeds_and_tilts

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "config" / "scenarios" / "ardupilot_hexa.toml"
G = 9.81
OFF = (1000,) * 16


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(SCENARIO)


def packet(count: int, pwm: tuple[int, ...] = OFF, rate: int = 1200) -> bytes:
    """A servo packet as ArduPilot sends it (16 or 32 channels)."""
    magic = MAGIC_16 if len(pwm) == 16 else MAGIC_32
    return struct.pack(f"<HHI{len(pwm)}H", magic, rate, count, *pwm)


def frame(count: int, pwm: tuple[int, ...] = OFF, rate: int = 1200) -> ServoPacket:
    pkt = parse_servo_packet(packet(count, pwm, rate))
    assert pkt is not None
    return pkt


def answer(data: bytes) -> dict:
    return json.loads(data)


# ------------------------------------------------------------------ packets


def test_servo_packets_16_and_32_channels() -> None:
    pwm16 = tuple(1000 + 10 * i for i in range(16))
    pwm32 = tuple(1000 + 5 * i for i in range(32))
    assert parse_servo_packet(packet(7, pwm16)) == ServoPacket(1200, 7, pwm16)
    assert parse_servo_packet(packet(2**32 - 1, pwm32, 400)) == ServoPacket(400, 2**32 - 1, pwm32)


@pytest.mark.parametrize("data", [
    b"", b"\x1aH", packet(1)[:-1], packet(1) + b"\0",  # short, long
    struct.pack("<HHI16H", 12345, 1200, 1, *OFF),  # wrong magic
    struct.pack("<HHI32H", MAGIC_16, 1200, 1, *(OFF * 2)),  # 16-channel magic, 32 values
    struct.pack("<HHI16H", MAGIC_32, 1200, 1, *OFF),  # 32-channel magic, 16 values
    b'{"timestamp":1}',
])
def test_bad_packets_are_not_servo_packets(data: bytes) -> None:
    assert parse_servo_packet(data) is None


def test_pwm_to_rotor_speed() -> None:
    rotors = (0, 1, 2, 3, 4, 5)
    speeds = rotor_speeds((0, 900, 1000, 1500, 2000, 2100), rotors, 1700.0)
    assert speeds == (0.0, 0.0, 0.0, 850.0, 1700.0, 1700.0)
    # channel order -> rotor order
    assert rotor_speeds((1500, 1000, 1000, 1000, 1000, 1000), (4, 1, 0, 3, 5, 2), 1700.0) == \
        (0.0, 0.0, 0.0, 0.0, 850.0, 0.0)


def test_step_is_arducopters_clock_step() -> None:
    assert step_us(1200) == 833 and step_us(400) == 2500 and step_us(1000) == 1000
    with pytest.raises(ConfigError):
        step_us(0)


# ------------------------------------------------------------------ the hexa X


def test_motor_map_follows_arducopters_hexa_x(scenario) -> None:
    assert motor_map(scenario.vehicle) == (4, 1, 0, 3, 5, 2)


def test_vehicles_that_are_not_arducopters_hexa_x_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"rotor 4 spins counter-clockwise.*motor 1.*backwards"):
        motor_map(load_vehicle(ROOT / "config/vehicles/hexa_planar.toml"))
    with pytest.raises(ConfigError, match="tilted out of the body plane"):
        motor_map(load_vehicle(ROOT / "config/vehicles/hexa_tilted.toml"))
    v = load_vehicle(ROOT / "config/vehicles/hexa_ardupilot.toml")
    turned = dataclasses.replace(v, arm_azimuth_rad=tuple(a + 0.2 for a in v.arm_azimuth_rad))
    with pytest.raises(ConfigError, match="no rotor at ArduCopter's hexa X motor 1"):
        motor_map(turned)


# Per ArduCopter hexa X motor (AP_MotorsMatrix: 1: 90 CW, 2: -90 CCW, 3: -30 CW, 4: 150 CCW,
# 5: 30 CCW, 6: -150 CW, angles clockwise from forward): the sign of the roll, pitch and yaw
# torque (body FRD) its thrust and drag put on the vehicle. Roll right is +, nose up is +,
# yaw right (clockwise seen from above) is +: a CCW propeller yaws the body right.
TORQUE_SIGNS_FRD = {1: (-1, 0, -1), 2: (1, 0, 1), 3: (1, 1, -1), 4: (-1, -1, 1),
                    5: (-1, 1, 1), 6: (1, -1, -1)}


@pytest.mark.parametrize("motor", sorted(TORQUE_SIGNS_FRD))
def test_each_motor_turns_the_body_as_arducopter_expects(scenario, motor: int) -> None:
    physics = JsonPhysics(scenario)
    pwm = [1000] * 16
    pwm[motor - 1] = 1600
    speeds = rotor_speeds(tuple(pwm), physics.rotor_of_motor, physics.plant.w_max)
    force_flu, torque_flu = physics.plant.rotor_wrench(speeds, (0.0,) * 6)
    roll, pitch, yaw = torque_flu[0], -torque_flu[1], -torque_flu[2]  # FLU -> FRD
    assert force_flu[2] > 0.0
    for value, sign in zip((roll, pitch, yaw), TORQUE_SIGNS_FRD[motor], strict=True):
        if sign == 0:
            assert abs(value) < 1e-9
        else:
            assert value * sign > 0.0, (motor, roll, pitch, yaw)


def test_equal_pwm_lifts_without_torque(scenario) -> None:
    physics = JsonPhysics(scenario)
    speeds = rotor_speeds((1583,) * 16, physics.rotor_of_motor, physics.plant.w_max)
    force, torque = physics.plant.rotor_wrench(speeds, (0.0,) * 6)
    assert force[2] == pytest.approx(scenario.vehicle.mass_kg * G, rel=0.01)  # ~hover
    assert max(abs(c) for c in torque) < 1e-9


# ------------------------------------------------------------------ the JSON answer


def test_answer_is_compact_json_between_newlines(scenario) -> None:
    physics = JsonPhysics(scenario)
    data, stepped = physics.frame(frame(0))
    assert stepped
    text = data.decode()
    assert text.startswith("\n{") and text.endswith("}\n") and text.count("\n") == 2
    assert not re.search(r"\s", text.strip())  # ArduPilot's parser skips exactly '":'
    msg = answer(data)
    assert set(msg) == {"timestamp", "imu", "position", "velocity", "quaternion"}
    assert set(msg["imu"]) == {"gyro", "accel_body"}
    for key in ("gyro", "accel_body"):
        assert re.search(rf'"{key}":\[[^,\]]+,[^,\]]+,[^,\]]+\]', text)
    assert re.search(r'"quaternion":\[[^,\]]+,[^,\]]+,[^,\]]+,[^,\]]+\]', text)


def test_at_rest_on_the_ground_facing_east(scenario) -> None:
    """The scenario's start (ENU/FLU identity): accel_body (0, 0, -g) in FRD, yaw +90 deg."""
    msg = answer(JsonPhysics(scenario).frame(frame(0))[0])
    assert msg["imu"]["accel_body"] == pytest.approx([0.0, 0.0, -G], abs=1e-12)
    assert msg["imu"]["gyro"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    assert msg["position"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    w, x, y, z = msg["quaternion"]
    assert math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))) == \
        pytest.approx(90.0)
    assert (w, x, y) == pytest.approx((math.sqrt(0.5), 0.0, 0.0), abs=1e-12)


def test_frames_of_a_moving_vehicle(scenario) -> None:
    """ENU/FLU state -> NED/FRD answer: position, velocity, rates, attitude, specific force."""
    physics = JsonPhysics(scenario)
    plant = physics.plant
    speeds, tilts = hover_speeds_and_tilts(plant)
    h = math.sqrt(0.5)
    s = plant.initial_state((1.0, 2.0, 3.0), on_ground=False, rotor_speed_rad_s=speeds,
                            tilt_rad=tilts, q_enu_flu=(h, 0.0, 0.0, h))  # body x north
    s = s._replace(v_enu_m_s=(0.5, -1.5, 2.0), omega_flu_rad_s=(0.1, 0.2, 0.3))
    msg = answer(state_json(1.5, plant, s))
    assert msg["timestamp"] == 1.5
    assert msg["position"] == pytest.approx([2.0, 1.0, -3.0])  # north, east, down
    assert msg["velocity"] == pytest.approx([-1.5, 0.5, -2.0])
    assert msg["imu"]["gyro"] == pytest.approx([0.1, -0.2, -0.3])
    assert msg["imu"]["accel_body"] == pytest.approx([0.0, 0.0, -G], abs=1e-9)  # hover thrust
    assert msg["quaternion"] == pytest.approx([1.0, 0.0, 0.0, 0.0], abs=1e-12)  # yaw 0
    # rolled right 30 deg: about the body's forward axis, which both FLU and FRD share,
    # turning the left wing (+y in FLU) up
    q = q_mul((h, 0.0, 0.0, h), q_exp((math.radians(30.0), 0.0, 0.0)))
    w, x, y, z = answer(state_json(0.0, plant, s._replace(q_enu_flu=q)))["quaternion"]
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    assert math.degrees(roll) == pytest.approx(30.0)


# ------------------------------------------------------------------ stepping


def test_new_frames_step_repeats_answer_again_backwards_restarts(scenario) -> None:
    physics = JsonPhysics(scenario)
    climb = (1800,) * 6 + (0,) * 10
    first, stepped = physics.frame(frame(0, climb))
    assert stepped and physics.state.time_us == 833
    again, stepped = physics.frame(frame(0, climb))
    assert not stepped and again == first and physics.state.time_us == 833
    assert physics.repeats == 1
    for n in range(1, 1201):
        physics.frame(frame(n, climb))
    assert physics.state.time_us == 1201 * 833 and physics.steps == 1201
    assert physics.state.p_enu_m[2] > 1.0  # a second at 80 % speed: it climbed
    physics.frame(frame(1205, climb))
    assert physics.skipped_frames == 4  # 1201..1204 never came
    # ArduPilot restarted: its frame count starts again
    data, stepped = physics.frame(frame(0))
    assert stepped and physics.reboots == 1
    assert physics.state.time_us == 833 and physics.state.p_enu_m == (0.0, 0.0, 0.0)
    assert physics.state.landed
    assert answer(data)["timestamp"] == pytest.approx(833.5e-6)
    assert physics.log_state().time_us == 1202 * 833 + 833  # the log's clock goes on


@pytest.mark.parametrize("rate", [1200, 1000, 400])
def test_arducopters_clock_moves_exactly_one_step_per_frame(scenario, rate: int) -> None:
    """ArduPilot adds each timestamp step to an integer microsecond clock, truncating
    (SIM_JSON.cpp: time_now_us += deltat * 1.0e6): it must move exactly as the plant."""
    physics = JsonPhysics(scenario)
    ap_us, last_s = 0, 0.0
    for n in range(30_000):
        ts = float(re.search(rb'"timestamp":([^,]+),', physics.frame(frame(n, rate=rate))[0])[1])
        ap_us = int(ap_us + (ts - last_s) * 1.0e6)
        last_s = ts
        assert ap_us == physics.state.time_us, n
    assert physics.state.time_us == 30_000 * (1_000_000 // rate)


def test_actuator_faults_count_from_the_first_spinning_frame(scenario) -> None:
    faulty = dataclasses.replace(
        scenario, actuator_faults=(ActuatorFault("rotor_off", 0, 0.5),))
    physics = JsonPhysics(faulty)
    for n in range(600):  # half a second with the motors off: the flight has not started
        physics.frame(frame(n))
    assert physics.flight_start_us is None
    spin = (1500,) * 6 + (0,) * 10
    for n in range(600, 1100):  # 0.42 s spinning: the fault (at 0.5 s) is not on yet
        physics.frame(frame(n, spin))
    assert physics.flight_start_us == 600 * 833
    assert min(physics.state.rotor_speed_rad_s) > 800.0
    for n in range(1100, 1400):
        physics.frame(frame(n, spin))
    speeds = physics.state.rotor_speed_rad_s
    assert speeds[0] < 50.0 and min(speeds[1:]) > 800.0  # rotor 0 (motor 3) is off


# ------------------------------------------------------------------ the server


def test_server_on_loopback(scenario, tmp_path: Path) -> None:
    """A scripted ArduPilot side: answers go to the sender only, repeats are answered
    without stepping, bad packets are counted and never answered; the truth log has one
    row per step; the server stops `end_time_s` after the first packet."""
    port = free_port()
    truth = tmp_path / "truth.ulg"
    server = Server(scenario, f"udpin:127.0.0.1:{port}", truth_log=truth, end_time_s=0.5)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    ap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    other = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ap.settimeout(5.0)
    other.settimeout(0.2)
    try:
        target = ("127.0.0.1", port)
        other.sendto(b"\x00\x01garbage", target)
        other.sendto(struct.pack("<HHI16H", MAGIC_16, 0, 1, *OFF), target)  # rate 0
        answers = []
        for n in range(601):
            pwm = OFF if n % 2 else (1000,) * 32
            ap.sendto(packet(n, pwm), target)
            answers.append(ap.recv(4096))
            if n == 10:
                ap.sendto(packet(n, pwm), target)  # a re-send: the same answer
                assert ap.recv(4096) == answers[-1]
        times = [answer(a)["timestamp"] for a in answers]
        assert all(b > a for a, b in itertools.pairwise(times))
        with pytest.raises(TimeoutError):
            other.recv(4096)
        thread.join(10.0)
        assert not thread.is_alive()  # 0.5 s after the first packet: 601 steps of 833 us
    finally:
        server.running = False
        thread.join(10.0)
        ap.close()
        other.close()
    st = server.stats()
    assert st["bad_packets"] == 2 and st["repeats"] == 1 and st["frames"] == 602
    assert st["steps"] == 601 and st["frame_rate_hz"] == 1200 and st["step_us"] == 833
    _, rows = read_topic(truth, "dq_truth")
    assert len(rows) == 601 and list(np.diff(rows[:, 0])) == [833.0] * 600
    assert "601 frames at 1200 Hz" in server.summary()


def test_server_takes_only_udpin(scenario) -> None:
    with pytest.raises(LinkError, match="UDP"):
        Server(scenario, "tcpin:127.0.0.1:0", truth_log=None, end_time_s=None)


def test_sensor_profiles_are_refused(scenario) -> None:
    """ArduPilot simulates its sensors from the exact state: a profile would be ignored."""
    from common.config.sensors import resolve_sensor_profile

    noisy = dataclasses.replace(scenario, sensors=resolve_sensor_profile("mocap-indoor"))
    with pytest.raises(ConfigError, match=r"mocap-indoor.*ArduPilot makes its own sensors"):
        JsonPhysics(noisy)
    truth = dataclasses.replace(scenario, sensors=resolve_sensor_profile("truth"))
    assert JsonPhysics(truth).frame(frame(0))[1]


def test_a_touchdown_is_in_the_accelerometer():
    """Given the impulse of a touchdown step, then accel_body holds it (the velocity
    change over the step), without it the resting g."""
    from sitl.firmware.ardupilot_json import state_json
    from sitl.plant import ActuatorCommand, Plant

    plant = Plant(load_scenario(ROOT / "config" / "scenarios" / "px4_hexa.toml").vehicle)
    a = plant.initial_state((0.0, 0.0, 0.0005), on_ground=False)._replace(
        v_enu_m_s=(0.0, 0.0, -1.0))
    b = plant.step(a, ActuatorCommand((0.0,) * 6, (0.0,) * 6))
    assert b.landed
    dv = plant.contact_dv_enu(a, b)
    with_impulse = json.loads(state_json(0.0, plant, b, dv).strip())["imu"]["accel_body"]
    resting = json.loads(state_json(0.0, plant, b).strip())["imu"]["accel_body"]
    assert resting == pytest.approx([0.0, 0.0, -plant.g])
    assert with_impulse == pytest.approx([0.0, 0.0, -plant.g - 1.0 / (plant.dt_us * 1e-6)])


def test_a_touchdown_reaches_arducopter_spread_over_50_ms_in_full(scenario):
    """Given a descent at 1 m/s onto the ground through the JSON protocol (1200 Hz frames),
    then the frames' accel_body beyond the resting g integrates to the velocity change
    (1 m/s up) and is spread over CONTACT_SPREAD_S (60 frames, none above 1/20 of it):
    ArduPilot's IMUs sample the latest frame at their own rates, and a one-frame impulse
    was taken 0, 1 or 2 times (EKF3 then 0.33-0.37 m off the ground after landings)."""
    from sitl.firmware.ardupilot_json import CONTACT_SPREAD_S

    phys = JsonPhysics(scenario)
    phys.state = phys.plant.initial_state((0.0, 0.0, 0.0005), on_ground=False)._replace(
        v_enu_m_s=(0.0, 0.0, -1.0))
    g = phys.plant.g
    excess = []
    for k in range(200):
        answer_text, _ = phys.frame(frame(k))
        excess.append(-json.loads(answer_text.strip())["imu"]["accel_body"][2] - g)
    dt = phys.plant.dt_us * 1e-6
    landed_at = next(k for k, x in enumerate(excess) if abs(x) > 1.0)
    assert sum(excess) * dt == pytest.approx(1.0, rel=1e-3)  # the whole 1 m/s, once
    assert max(excess) * dt < 1.0 / 20
    spread = [k for k, x in enumerate(excess) if abs(x) > 1.0]
    assert spread[-1] - landed_at + 1 == round(CONTACT_SPREAD_S / dt)
