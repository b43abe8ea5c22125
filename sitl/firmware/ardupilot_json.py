"""`sitl --protocol ardupilot-json`: the plant as physics for ArduPilot's JSON SITL interface
(ArduPilot's `libraries/SITL/SIM_JSON.cpp`, started as `--model JSON:IP`).

ArduPilot sends one servo packet per physics frame from its own UDP port: uint16 magic
(18458 with 16 PWM channels, 29569 with 32), uint16 frame_rate, uint32 frame_count, then the
PWM values in microseconds, little-endian. It blocks until the physics answers with one JSON
line, and re-sends the same frame after a second without one. Here:

- a new frame count steps the plant once under that frame's PWM and answers with the state
  after the step; a repeated one (ArduPilot's re-send) is answered again without stepping;
  one that goes back is ArduPilot restarting: the plant starts again from the scenario's
  initial state at time 0 (the truth log goes on, its clock continuing after the restart);
- the step is 1/frame_rate truncated to whole microseconds (833 us at ArduCopter's 1200 Hz),
  which is how far ArduPilot's own clock moves per frame: it adds each timestamp step to an
  integer microsecond clock, truncating. Each step is sent as dt + 0.5 us, so that the
  truncation gives exactly dt whatever the rounding of the decimal timestamps (the
  timestamp runs ahead of the plant clock by 0.5 us per frame; ArduPilot uses only its
  differences);
- the answer is compact JSON between newlines ("\\n{...}\\n": ArduPilot reads the text
  between its last two newlines, and its parser skips exactly `":` after a key, so no
  spaces): timestamp (s), imu gyro (rad/s) and accel_body (specific force, m/s^2) in body
  FRD, position (m) and velocity (m/s) in local NED from the home, quaternion NED <- FRD
  (w, x, y, z). ArduPilot makes GPS, barometer and compass from these. A touchdown's
  velocity change is in accel_body spread evenly over CONTACT_SPREAD_S (`ContactSpread`),
  not in the one frame it happened in: ArduPilot's IMUs sample the latest frame on their
  own clocks (1 kHz and 800 Hz), so a one-frame impulse was taken once, twice or not at
  all, and EKF3's height after a landing was then off by up to 0.37 m;
- anything else on the port (a wrong magic, a short or long datagram) is counted and
  ignored.

Output channels 1..6 are ArduCopter's hexa X motors (`ARDUCOPTER_HEXA_X`), each mapped to
the vehicle's rotor at its arm angle, whose spin must be ArduCopter's (`motor_map`); PWM to
rotor speed is linear from PWM_OFF_US (off; PWM 0 too) to PWM_FULL_US (w_max); the tilts are
held at 0. The scenario's disturbances and actuator faults count from the first frame that
spins a rotor (ArduCopter arms with its motors at MOT_SPIN_ARM), as the dqflight protocol's
count from the first armed answer.
"""

from __future__ import annotations

import select
import struct
import time
from pathlib import Path
from typing import Any, NamedTuple

from common.config.scenario import ConfigError, Scenario, VehicleConfig
from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.links import LinkError, UdpLink, open_link, parse_url
from common.wire.mavlink import MAV
from sitl.actuator_faults import ActuatorFaults
from sitl.firmware.rotor_layout import rotors_for_outputs
from sitl.plant import (
    ActuatorCommand,
    ContactSpread,
    Plant,
    PlantState,
    Vec3,
    initial_state,
    scenario_plant,
)
from sitl.truth_log import TruthLog, flushed

MAGIC_16 = 18458  # servo packet with 16 PWM channels
MAGIC_32 = 29569  # with 32 (ArduPilot's SERVO_32_ENABLE = 1)
_HEADER = struct.Struct("<HHI")  # magic, frame_rate, frame_count
_PWM = {MAGIC_16: struct.Struct("<16H"), MAGIC_32: struct.Struct("<32H")}
PACKET_BYTES = {magic: _HEADER.size + pwm.size for magic, pwm in _PWM.items()}

PWM_OFF_US = 1000  # at or below: the rotor is off (ArduPilot's MOT_PWM_MIN)
PWM_FULL_US = 2000  # at or above: w_max (MOT_PWM_MAX)

# ArduCopter's hexa X (FRAME_CLASS 2, FRAME_TYPE 1; AP_MotorsMatrix): per output channel
# 1..6, the arm angle clockwise from forward (deg, seen from above) and the propeller's spin
# seen from above (+1 counter-clockwise, -1 clockwise).
ARDUCOPTER_HEXA_X: tuple[tuple[float, int], ...] = (
    (90.0, -1), (-90.0, 1), (-30.0, -1), (150.0, 1), (30.0, 1), (-150.0, -1))
CONTACT_SPREAD_S = 0.05  # a touchdown's deceleration, as the px4-default sensor profile has it
LOG_BATCH = 64  # truth records handed to the kernel together (and whenever the link idles)


class ServoPacket(NamedTuple):
    frame_rate_hz: int
    frame_count: int
    pwm_us: tuple[int, ...]


def parse_servo_packet(data: bytes) -> ServoPacket | None:
    """The servo packet in a datagram, None when it is not one (magic or length wrong)."""
    if len(data) < _HEADER.size:
        return None
    magic, rate, count = _HEADER.unpack_from(data)
    pwm = _PWM.get(magic)
    if pwm is None or len(data) != _HEADER.size + pwm.size:
        return None
    return ServoPacket(rate, count, pwm.unpack_from(data, _HEADER.size))


def step_us(frame_rate_hz: int) -> int:
    """The plant's step for a frame rate: 1/rate truncated to whole microseconds, as far as
    ArduPilot's clock moves per frame; ConfigError for a rate of 0."""
    if frame_rate_hz <= 0:
        raise ConfigError(f"ardupilot-json: frame rate {frame_rate_hz} Hz")
    return 1_000_000 // frame_rate_hz


def motor_map(vehicle: VehicleConfig) -> tuple[int, ...]:
    """The vehicle's rotor for each of ArduCopter's hexa X motors (channel order): the rotor
    at the motor's arm angle, which must lie in the body's plane and spin as ArduCopter's
    propeller there; ConfigError naming the first that does not."""
    return rotors_for_outputs(vehicle, ARDUCOPTER_HEXA_X, "ArduCopter's hexa X")


def rotor_speeds(pwm_us: tuple[int, ...], rotor_of_motor: tuple[int, ...],
                 w_max_rad_s: float) -> tuple[float, ...]:
    """Rotor speeds (rad/s, rotor order) from the motors' PWM (channel order): linear from
    PWM_OFF_US (0) to PWM_FULL_US (w_max), clamped; PWM 0 is off."""
    speeds = [0.0] * len(rotor_of_motor)
    span = PWM_FULL_US - PWM_OFF_US
    for motor, rotor in enumerate(rotor_of_motor):
        x = (pwm_us[motor] - PWM_OFF_US) / span
        speeds[rotor] = w_max_rad_s * (0.0 if x <= 0.0 else (1.0 if x >= 1.0 else x))
    return tuple(speeds)


def state_json(timestamp_s: float, plant: Plant, s: PlantState,
               contact_dv_enu: Vec3 = (0.0, 0.0, 0.0)) -> bytes:
    """The JSON line ArduPilot reads for the state `s`, between newlines, compact; the
    accelerometer holds `contact_dv_enu` (ENU m/s) of ground impulse over the step."""
    gx, gy, gz = flu_to_frd(s.omega_flu_rad_s)
    ax, ay, az = flu_to_frd(plant.specific_force_flu(s, contact_dv_enu=contact_dv_enu))
    px, py, pz = enu_to_ned(s.p_enu_m)
    vx, vy, vz = enu_to_ned(s.v_enu_m_s)
    qw, qx, qy, qz = q_enu_flu_to_ned_frd(s.q_enu_flu)
    return (f'\n{{"timestamp":{timestamp_s!r},"imu":{{"gyro":[{gx!r},{gy!r},{gz!r}],'
            f'"accel_body":[{ax!r},{ay!r},{az!r}]}},"position":[{px!r},{py!r},{pz!r}],'
            f'"velocity":[{vx!r},{vy!r},{vz!r}],'
            f'"quaternion":[{qw!r},{qx!r},{qy!r},{qz!r}]}}\n').encode()


class JsonPhysics:
    """The protocol without sockets: servo packets in, JSON answers out (`frame`)."""

    def __init__(self, scenario: Scenario) -> None:
        if scenario.uses_sensors:
            assert scenario.sensors is not None
            raise ConfigError(f"--protocol ardupilot-json: sensor profile "
                              f"'{scenario.sensors.name}': ArduPilot makes its own sensors "
                              "from the exact state (its SIM_* parameters add their noise); "
                              "use the truth profile")
        self.scenario = scenario
        self.rotor_of_motor = motor_map(scenario.vehicle)
        self._plants: dict[int, Plant] = {}
        self.plant = self._plant(step_us(1200))
        self.state = initial_state(scenario, self.plant)
        self.faults = ActuatorFaults(scenario.actuator_faults)
        self.last_count: int | None = None
        self.last_answer = b""
        self.steps = 0  # plant steps, all sessions
        self.repeats = 0  # repeated frame counts answered without stepping
        self.reboots = 0  # frame counts that went back: ArduPilot restarted
        self.skipped_frames = 0  # frame counts jumped over (never seen)
        self.frame_rate_hz = 0
        self.flight_start_us: int | None = None  # the first frame that spins a rotor
        self.time_offset_us = 0  # truth-log clock at the latest restart
        self._session_steps = 0  # steps since the latest restart (each sent as dt + 0.5 us)
        self._tilts = (0.0,) * scenario.vehicle.n_rotors
        self._contact = ContactSpread(round(CONTACT_SPREAD_S * 1e6))

    def _plant(self, dt_us: int) -> Plant:
        plant = self._plants.get(dt_us)
        if plant is None:
            plant = self._plants[dt_us] = scenario_plant(self.scenario, dt_us)
        return plant

    def timestamp_s(self) -> float:
        """The state's timestamp as ArduPilot is sent it (plant clock + 0.5 us per step)."""
        return (self.state.time_us + 0.5 * self._session_steps) * 1e-6

    def frame(self, pkt: ServoPacket) -> tuple[bytes, bool]:
        """The answer to a servo packet and whether the plant stepped for it."""
        if self.last_count is not None and pkt.frame_count == self.last_count:
            self.repeats += 1
            return self.last_answer, False
        if self.last_count is not None and pkt.frame_count < self.last_count:
            self.restart()
        elif self.last_count is not None:
            self.skipped_frames += pkt.frame_count - self.last_count - 1
        self.last_count = pkt.frame_count
        self.frame_rate_hz = pkt.frame_rate_hz
        plant = self._plant(step_us(pkt.frame_rate_hz))
        self.plant = plant
        speeds = rotor_speeds(pkt.pwm_us, self.rotor_of_motor, plant.w_max)
        if self.flight_start_us is None and any(speeds):
            self._start_flight()
        cmd = self.faults.apply(ActuatorCommand(speeds, self._tilts), self.state)
        prev = self.state
        self.state = plant.step(self.state, cmd)
        self.steps += 1
        self._session_steps += 1
        dv = self._contact.take(plant.contact_dv_enu(prev, self.state), plant.dt_us)
        self.last_answer = state_json(self.timestamp_s(), plant, self.state, dv)
        return self.last_answer, True

    def _start_flight(self) -> None:
        t_us = self.state.time_us
        self.flight_start_us = t_us
        for plant in self._plants.values():
            plant.disturbance = plant.disturbance.from_time(t_us * 1e-6)
        self.faults.start_flight(t_us)

    def restart(self) -> None:
        """ArduPilot restarted: the plant starts again from its initial state at time 0."""
        self.reboots += 1
        self.time_offset_us += self.state.time_us
        self._plants = {}
        self.plant = self._plant(self.plant.dt_us)
        self.state = initial_state(self.scenario, self.plant)
        self.faults = ActuatorFaults(self.scenario.actuator_faults)
        self.flight_start_us = None
        self._session_steps = 0
        self._contact = ContactSpread(round(CONTACT_SPREAD_S * 1e6))
        self.last_count = None

    def log_state(self) -> PlantState:
        """The state as the truth log records it (its clock continues across restarts)."""
        if not self.time_offset_us:
            return self.state
        return self.state._replace(time_us=self.state.time_us + self.time_offset_us)


class Server:
    """The plant behind ArduPilot's JSON interface on a udpin link (sitl.node's
    FirmwareServer): answers each servo packet to its sender until `running` is cleared or
    `end_time_s` of simulated time has passed since the first packet."""

    def __init__(self, scenario: Scenario, link_url: str, *, truth_log: Path | None,
                 end_time_s: float | None, system_id: int = 1) -> None:
        url = parse_url(link_url)
        if url.scheme != "udpin":
            raise LinkError(f"link '{link_url}': ArduPilot's JSON interface is UDP: expected "
                            "udpin:HOST:PORT (ArduPilot sends to port 9002)")
        self.physics = JsonPhysics(scenario)
        self.system_id = system_id  # no MAVLink on this link: kept for the common contract
        self.end_us = None if end_time_s is None else round(end_time_s * 1e6)
        link = open_link(url)
        assert isinstance(link, UdpLink)
        self.link = link
        self.log = TruthLog(truth_log, scenario.name) if truth_log else None
        self._unflushed = 0
        self.bad_packets = 0
        self.frames = 0  # servo packets answered (steps and repeats)
        self.running = True
        self.first_wall_s: float | None = None
        self.last_wall_s = 0.0
        self.first_time_us = 0

    @property
    def state(self) -> PlantState:
        return self.physics.state

    def handle(self, peer: object, data: bytes) -> None:
        """One datagram: answered to its sender if it is a servo packet, else counted."""
        pkt = parse_servo_packet(data)
        if pkt is None or pkt.frame_rate_hz == 0:
            self.bad_packets += 1
            return
        if self.first_wall_s is None:
            self.first_wall_s = time.monotonic()
            self.first_time_us = self.physics.log_state().time_us
        reboots = self.physics.reboots
        answer, stepped = self.physics.frame(pkt)
        self.link.send_to(answer, peer)
        self.frames += 1
        self.last_wall_s = time.monotonic()
        if self.log is not None:
            if self.physics.reboots != reboots:
                self.log.log(self.physics.time_offset_us, MAV.MAV_SEVERITY_WARNING,
                             "ArduPilot restarted (its frame count went back): the plant "
                             "starts again from its initial state")
            if stepped:
                self.log.record(self.physics.log_state())
                self._unflushed += 1
                if self._unflushed >= LOG_BATCH:
                    self._flush_log()

    def _at_end(self) -> bool:
        return (self.end_us is not None and self.first_wall_s is not None
                and self.physics.log_state().time_us - self.first_time_us >= self.end_us)

    def _flush_log(self) -> None:
        self._unflushed = 0
        self.log = flushed(self.log, self.state.time_us)

    def run(self) -> None:
        try:
            fds = self.link.filenos()
            while self.running and not self._at_end():
                if not select.select(fds, [], [], 0.0)[0]:
                    if self._unflushed:
                        self._flush_log()  # idle: what is logged reaches the file
                    if not select.select(fds, [], [], 0.1)[0]:
                        continue
                for peer, data in self.link.recv():
                    self.handle(peer, data)
                    if self._at_end():
                        break
        finally:
            self.close()

    def stats(self) -> dict[str, Any]:
        p = self.physics
        wall = (self.last_wall_s - self.first_wall_s) if self.first_wall_s is not None else 0.0
        sim_s = (p.log_state().time_us - self.first_time_us) * 1e-6
        return {"frames": self.frames, "steps": p.steps, "repeats": p.repeats,
                "reboots": p.reboots, "skipped_frames": p.skipped_frames,
                "bad_packets": self.bad_packets, "frame_rate_hz": p.frame_rate_hz,
                "step_us": p.plant.dt_us, "simulated_s": sim_s, "wall_s": wall,
                "frames_per_wall_s": p.steps / wall if wall > 0 else 0.0,
                "real_time_factor": sim_s / wall if wall > 0 else 0.0}

    def summary(self) -> str:
        st = self.stats()
        return (f"stopped at t = {self.state.time_us * 1e-6:.3f} s after {st['steps']} frames "
                f"at {st['frame_rate_hz']} Hz ({st['step_us']} us steps); {st['repeats']} "
                f"repeated, {st['reboots']} restarts, {st['bad_packets']} bad packets; "
                f"{st['real_time_factor']:.1f}x real time")

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
            self.log = None
        self.link.close()
