"""A scripted PX4 for `sitl --protocol px4-hil`, written from PX4's own reading code
(src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp), so that the protocol is
tested without a PX4 build. It does what that module does and checks what it relies on:

- connects to the simulator as a TCP client, sends one HEARTBEAT (autopilot 12) and asks
  HIL_STATE_QUATERNION at 5000 us (SET_MESSAGE_INTERVAL), as `run()` and `send()` do;
- takes its clock from HIL_SENSOR id 0 (`px4_clock_settime`), publishes accel, gyro, mag
  and baro only when all of a sensor's `fields_updated` bits are set (`update_sensors`,
  SensorSource: ACCEL 0b111, GYRO 0b111000, MAG 0b111000000, BARO 0b1101000000000),
  reads HIL_GPS in degE7, mm, cm, cm/s and HIL_STATE_QUATERNION in degE7, mm, cm/s;
- answers nothing while it "starts up" (PX4 sends HIL_ACTUATOR_CONTROLS only once its
  outputs are published), then answers at its control rate (`control_hz`, PX4's SITL 250
  Hz): a HIL_SENSOR gets one HIL_ACTUATOR_CONTROLS, stamped with its clock, only when that
  clock has reached the next control tick (a multiple of the control period), as PX4's
  sender thread sends only when actuator_outputs update (flags bit 0: lockstep; mode
  1 | 128 when armed; motors 0..1 on the hexa X outputs, zero when disarmed); or, with
  `rate_max_hz`, at PX4's rate-limited angular velocity publication (IMU_GYRO_RATEMAX in
  VehicleAngularVelocity), whose intervals in samples vary (2 or 3 at a 1 kHz IMU);
- flags stale sensors as PX4's DataValidator does (src/modules/sensors/data_validator/
  DataValidator.cpp): a sensor whose every axis repeats within 1e-6 for more than 100
  samples in a row (1,000 for the magnetometer) is reported in `Report.stale`;
- flies: a hover and position controller on the ground truth (HIL_STATE_QUATERNION), mixed
  onto PX4's hexa X outputs with PX4's allocation geometry (airframe 6001_hexa_x), so a
  wrong motor order, spin or axis in the plant shows as a vehicle that does not hold.

Every few hundred samples it holds its answer back for a while (`stall_s`, shorter than the
plant's GRACE_S) and looks whether the plant sent anything meanwhile (a plant that steps
without the answer would have; `Report.stall_sends`, which a test judges against the steps
past the plant records: a thread of a test starved on a busy machine may hold its answer
longer than the grace). Options model what PX4 was measured doing beside that:
an answer to every sample while it starts (`every_sample_until_s`), one answer never
sent (`withhold_at_s`), and no answers at all for a while (`mute_at_s`, `mute_wall_s`).
"""

from __future__ import annotations

import math
import select
import socket
import time
from dataclasses import dataclass, field

import numpy as np

from common.config.scenario import VehicleConfig
from common.geodetic import geodetic_to_ned
from common.wire.mavlink import MAV, encoder, pack, parser

ACCEL = 0b111
GYRO = 0b111000
MAG = 0b111000000
BARO = 0b1101000000000
DIFF_PRESS = 0b10000000000
MODE_CUSTOM = 1
MODE_ARMED = 128
# PX4's hexa X (6001_hexa_x): CA_ROTORn_PX, _PY (FRD, normalised) and the sign of _KM
# (+ counter-clockwise seen from above), per main output 1..6.
HEXA_X = ((0.0, 0.5, -1), (0.0, -0.5, 1), (0.43, -0.25, -1), (-0.43, 0.25, 1),
          (0.43, 0.25, 1), (-0.43, -0.25, -1))


@dataclass
class Sample:
    time_usec: int
    fields: int
    acc: tuple[float, float, float]
    gyro: tuple[float, float, float]
    mag: tuple[float, float, float]
    abs_pressure: float
    pressure_alt: float
    temperature: float
    diff_pressure: float
    sensor_id: int


@dataclass
class Report:
    samples: list[Sample] = field(default_factory=list)
    gps: list[tuple[int, object]] = field(default_factory=list)  # (clock, HIL_GPS)
    states: list[tuple[int, object]] = field(default_factory=list)  # (clock, HSQ)
    acks: list[object] = field(default_factory=list)
    odometry: list[object] = field(default_factory=list)  # motion capture (MOCAP)
    other: list[str] = field(default_factory=list)
    answers: list[int] = field(default_factory=list)  # time_usec of each answer sent
    answer_wall_s: list[float] = field(default_factory=list)  # and when (monotonic s)
    published: dict[str, int] = field(default_factory=lambda: dict.fromkeys(
        ("accel", "gyro", "mag", "baro", "diff_press"), 0))
    violations: list[str] = field(default_factory=list)
    stalls: int = 0  # answers held back and checked
    # the samples whose held-back answer the plant did not wait for (it sent meanwhile),
    # with when that was seen (monotonic s): judged against the plant's steps past
    stall_sends: list[tuple[int, float]] = field(default_factory=list)
    stale: dict[str, int] = field(default_factory=dict)  # sensor -> clock when flagged
    closed_by_plant: bool = False
    wall_s: float = 0.0


STALE_LIMIT = {"accel": 100, "gyro": 100, "baro": 100, "mag": 1000}  # DataValidator
STALE_EPS = 1e-6


class StaleCheck:
    """PX4's DataValidator stale rule: more than `limit` samples in a row equal to the
    previous within 1e-6 on every axis."""

    def __init__(self) -> None:
        self.last: dict[str, tuple[float, ...]] = {}
        self.equal: dict[str, int] = dict.fromkeys(STALE_LIMIT, 0)

    def put(self, name: str, value: tuple[float, ...], t_us: int, report: Report) -> None:
        prev = self.last.get(name)
        self.last[name] = value
        if prev is not None and all(abs(a - b) < STALE_EPS
                                    for a, b in zip(prev, value, strict=True)):
            self.equal[name] += 1
            if self.equal[name] > STALE_LIMIT[name] and name not in report.stale:
                report.stale[name] = t_us
        else:
            self.equal[name] = 0


class HoverController:
    """Position (NED) and attitude PD on the ground truth, mixed onto PX4's hexa X."""

    def __init__(self, vehicle: VehicleConfig) -> None:
        self.m = vehicle.mass_kg
        self.g = vehicle.gravity_m_s2
        self.j = vehicle.inertia_diag_kg_m2
        self.t_max = vehicle.thrust_coeff * vehicle.rotor_speed_max_rad_s ** 2
        km = vehicle.drag_coeff / vehicle.thrust_coeff
        arm = vehicle.arm_length_m
        cols = []
        for px, py, spin in HEXA_X:
            r = math.hypot(px, py)
            x, y = arm * px / r, arm * py / r
            cols.append((-y, x, spin * km, 1.0))  # roll, pitch, yaw torque, thrust per N
        self.pinv = np.linalg.pinv(np.array(cols).T)
        self.home: tuple[float, float, float] | None = None
        self.yaw_sp: float | None = None

    def outputs(self, hsq: object, target_ned: tuple[float, float, float]) -> list[float]:
        q = hsq.attitude_quaternion  # type: ignore[attr-defined]
        w, x, y, z = q
        roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
        yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        lat, lon, alt = hsq.lat * 1e-7, hsq.lon * 1e-7, hsq.alt * 1e-3  # type: ignore[attr-defined]
        if self.home is None:
            self.home = (lat, lon, alt)
            self.yaw_sp = yaw
        n, e, d = geodetic_to_ned(lat, lon, alt, *self.home)
        vn, ve, vd = hsq.vx / 100, hsq.vy / 100, hsq.vz / 100  # type: ignore[attr-defined]
        g = self.g
        a_n = max(-3.0, min(3.0, 1.2 * (target_ned[0] - n) - 1.8 * vn))
        a_e = max(-3.0, min(3.0, 1.2 * (target_ned[1] - e) - 1.8 * ve))
        a_d = max(-4.0, min(4.0, 3.0 * (target_ned[2] - d) - 3.0 * vd))
        c, s = math.cos(yaw), math.sin(yaw)
        pitch_sp = max(-0.3, min(0.3, -(a_n * c + a_e * s) / g))
        roll_sp = max(-0.3, min(0.3, (-a_n * s + a_e * c) / g))
        thrust = self.m * (g - a_d) / max(0.5, math.cos(roll) * math.cos(pitch))
        assert self.yaw_sp is not None
        e_yaw = (self.yaw_sp - yaw + math.pi) % (2 * math.pi) - math.pi
        p, qr, r = hsq.rollspeed, hsq.pitchspeed, hsq.yawspeed  # type: ignore[attr-defined]
        tau = (self.j[0] * (49.0 * (roll_sp - roll) - 12.0 * p),
               self.j[1] * (49.0 * (pitch_sp - pitch) - 12.0 * qr),
               self.j[2] * (9.0 * e_yaw - 5.0 * r))
        per_motor = self.pinv @ np.array([*tau, thrust])
        return [math.sqrt(min(max(t, 0.0), self.t_max) / self.t_max) for t in per_motor]


class ScriptedPX4:
    """PX4's simulator module against the plant on 127.0.0.1:`port`."""

    def __init__(self, port: int, vehicle: VehicleConfig, *, sysid: int = 1,
                 answer_after_s: float = 0.3, arm_at_s: float = 1.0,
                 waypoints: tuple[tuple[float, tuple[float, float, float]], ...] = (),
                 stall_every: int = 0, stall_s: float = 0.02, control_hz: float = 250.0,
                 withhold_at_s: float | None = None, rate_max_hz: float | None = None,
                 every_sample_until_s: float = 0.0, mute_at_s: float | None = None,
                 mute_wall_s: float = 1.5) -> None:
        self.port = port
        self.sysid = sysid
        self.answer_after_us = round(answer_after_s * 1e6)
        self.arm_at_us = round(arm_at_s * 1e6)
        self.waypoints = waypoints  # (from time s, NED target); before the first: on ground
        self.stall_every = stall_every
        self.stall_s = stall_s
        self.control_us = round(1e6 / control_hz)
        self.next_tick_us = 0  # answer the first sample at or after it
        # PX4's rate-limited angular velocity instead of control ticks: IMU_GYRO_RATEMAX
        self.rate_min_us = None if rate_max_hz is None else round(1e6 / rate_max_hz)
        self.last_publish_us = 0
        # the one answer never sent (the first control tick at or after this time)
        self.withhold_us = None if withhold_at_s is None else round(withhold_at_s * 1e6)
        self.withheld: int | None = None  # the sample whose answer was withheld
        # PX4's start-up, as measured: an answer to every sample until this clock
        self.every_sample_until_us = round(every_sample_until_s * 1e6)
        # no answers at all for `mute_wall_s` of wall time from the first sample at or
        # after this clock (a firmware that publishes no outputs for a while)
        self.mute_us = None if mute_at_s is None else round(mute_at_s * 1e6)
        self.mute_wall_s = mute_wall_s
        self.muted_s: float | None = None  # wall time the silence began
        self.muted_samples = 0
        self.stale_check = StaleCheck()
        self.controller = HoverController(vehicle)
        self.mav = encoder(sysid, MAV.MAV_COMP_ID_AUTOPILOT1)
        self.decoder = parser()
        self.clock_us = 0
        self.hsq: object | None = None
        self.sock: socket.socket | None = None

    def connect(self, timeout_s: float = 20.0) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            try:
                s.connect(("127.0.0.1", self.port))
                break
            except OSError:
                s.close()
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        self.sock = s
        hb = MAV.MAVLink_heartbeat_message(0, 12, 0, 0, 0, 3)
        ask = MAV.MAVLink_command_long_message(0, 0, MAV.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                               MAV.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, 5e3,
                                               0, 0, 0, 0, 0)
        s.sendall(pack(self.mav, hb) + pack(self.mav, ask))

    def send(self, data: bytes) -> None:
        assert self.sock is not None
        self.sock.sendall(data)

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def _target(self, t_us: int) -> tuple[float, float, float] | None:
        target = None
        for t_s, ned in self.waypoints:
            if t_us >= t_s * 1e6:
                target = ned
        return target

    def _answer(self, report: Report) -> None:
        armed = self.clock_us >= self.arm_at_us and self.hsq is not None
        controls = [0.0] * 16
        target = self._target(self.clock_us)
        if armed and target is not None:
            controls[:6] = self.controller.outputs(self.hsq, target)
        mode = MODE_CUSTOM | (MODE_ARMED if armed else 0)
        msg = MAV.MAVLink_hil_actuator_controls_message(self.clock_us, controls, mode, 1)
        n = len(report.answers)
        if self.stall_every and n and n % self.stall_every == 0:
            time.sleep(self.stall_s)  # the plant must not step meanwhile (but past its grace)
            assert self.sock is not None
            if select.select([self.sock], [], [], 0)[0]:
                report.stall_sends.append((self.clock_us, time.monotonic()))
            report.stalls += 1
        self.send(pack(self.mav, msg))
        report.answers.append(self.clock_us)
        report.answer_wall_s.append(time.monotonic())

    def _hil_sensor(self, m: object, report: Report) -> None:
        f = m.fields_updated  # type: ignore[attr-defined]
        smp = Sample(m.time_usec, f, (m.xacc, m.yacc, m.zacc),  # type: ignore[attr-defined]
                     (m.xgyro, m.ygyro, m.zgyro), (m.xmag, m.ymag, m.zmag),  # type: ignore[attr-defined]
                     m.abs_pressure, m.pressure_alt, m.temperature,  # type: ignore[attr-defined]
                     m.diff_pressure, m.id)  # type: ignore[attr-defined]
        if smp.sensor_id == 0:
            if report.samples and smp.time_usec <= self.clock_us:
                report.violations.append(f"clock went from {self.clock_us} to "
                                         f"{smp.time_usec} us")
            self.clock_us = smp.time_usec
        report.samples.append(smp)
        values = {"accel": smp.acc, "gyro": smp.gyro, "mag": smp.mag,
                  "baro": (smp.abs_pressure * 100.0,)}  # PX4 validates pressure in Pa
        for name, mask in (("accel", ACCEL), ("gyro", GYRO), ("mag", MAG), ("baro", BARO),
                           ("diff_press", DIFF_PRESS)):
            if f & mask == mask:
                report.published[name] += 1
                if name in values:
                    self.stale_check.put(name, values[name], smp.time_usec, report)
        if smp.sensor_id == 0 and self.mute_us is not None and self.clock_us >= self.mute_us:
            now = time.monotonic()
            if self.muted_s is None:
                self.muted_s = now
            if now - self.muted_s < self.mute_wall_s:
                self.muted_samples += 1
                return
        starting = self.clock_us < self.every_sample_until_us
        if smp.sensor_id == 0 and self.clock_us >= self.answer_after_us and \
                (starting or self.clock_us >= self.next_tick_us):
            self.next_tick_us = self._next_tick()
            if self.withhold_us is not None and self.withheld is None and \
                    self.clock_us >= self.withhold_us:
                self.withheld = self.clock_us  # this answer never comes
                return
            self._answer(report)

    def _next_tick(self) -> int:
        """The first clock the next answer may come at: the next control tick, or with
        `rate_max_hz` VehicleAngularVelocity::CalibrateAndPublish's rule (publish when the
        minimum interval has passed since `_last_publish`, then shift that on by the
        interval, no further behind the sample than one interval): at 400 Hz, every 3 or
        2 samples at a 1 kHz IMU, 1 or 2 at 500 Hz."""
        if self.rate_min_us is None:
            return (self.clock_us // self.control_us + 1) * self.control_us
        step = self.rate_min_us
        self.last_publish_us = min(max(self.last_publish_us + step, self.clock_us - step),
                                   self.clock_us)
        return self.last_publish_us + step

    def _handle(self, data: bytes, report: Report) -> None:
        for m in self.decoder.parse_buffer(data) or []:
            kind = m.get_type()
            if kind == "HIL_SENSOR":
                self._hil_sensor(m, report)
            elif kind == "HIL_GPS":
                report.gps.append((self.clock_us, m))
            elif kind == "HIL_STATE_QUATERNION":
                self.hsq = m
                report.states.append((self.clock_us, m))
            elif kind == "COMMAND_ACK":
                report.acks.append(m)
            elif kind == "ODOMETRY":
                report.odometry.append(m)
            else:
                report.other.append(kind)

    def run(self, until_s: float, wall_timeout_s: float = 60.0) -> Report:
        """Until the clock reaches `until_s`, the plant closes the link or the wall time
        runs out; the link stays open (close() it)."""
        report = Report()
        assert self.sock is not None
        start = time.monotonic()
        until_us = round(until_s * 1e6)
        while self.clock_us < until_us and time.monotonic() - start < wall_timeout_s:
            if not select.select([self.sock], [], [], 0.5)[0]:
                continue
            try:
                data = self.sock.recv(65536)
                if data:
                    self._handle(data, report)
            except (BrokenPipeError, ConnectionResetError):
                data = b""
            if not data:
                report.closed_by_plant = True
                break
        report.wall_s = time.monotonic() - start
        return report
