"""`sitl --protocol px4-hil`: the plant as physics for PX4, through PX4's simulator MAVLink
API (src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp). PX4 connects as a TCP
client (`simulator_mavlink start -c 4560`); the plant is the server (`tcpin:`, one firmware
at a time: a second connection is closed at once).

Out, all stamped with the simulation clock: HIL_SENSOR (sensor id 0, one per IMU sample,
FRD specific force in m/s^2 and rate in rad/s, `fields_updated` 0x3F; a magnetometer
sample in gauss FRD adds 0x1C0, a barometer sample 0x1A00: abs_pressure in hPa,
pressure_alt in m AMSL, temperature in degC, the bits PX4 needs all of to publish that
sensor), HIL_GPS (degE7, mm AMSL, cm/s NED, cdeg, eph/epv cm, 3D fix, the profile's
satellites) and HIL_STATE_QUATERNION (ground truth: NED->FRD quaternion, FRD rates, degE7,
mm, cm/s, mG), and with a named sensor profile the motion-capture pose as ODOMETRY (PX4
publishes it as vehicle_mocap_odometry). The magnetometer and barometer ride on the IMU's
HIL_SENSOR (PX4 reads them only there); HIL_GPS and HIL_STATE_QUATERNION go out at the
first IMU sample at or after they fall due, just before it.

Sensors: the scenario's profile, else config/sensors/px4-default.toml, noisy on every
sensor so that PX4's DataValidator never calls one stale (`sitl.firmware.px4_profile`; an exact
profile is served with a one-line warning). Any IMU rate from 100 Hz whose period is a
whole number of microseconds. HIL_STATE_QUATERNION at the interval PX4 asks with
SET_MESSAGE_INTERVAL (200 Hz until it asks), answered with COMMAND_ACK.

In: HIL_ACTUATOR_CONTROLS (motor outputs 0..1 on PX4's hexa X order, `sitl.firmware.px4_wire`).

Lockstep as PX4 runs it. The samples start when the firmware's first packet on a connection
arrives (PX4 sends a HEARTBEAT first). PX4's clock is the time of the latest HIL_SENSOR; it
answers only when its outputs update, at its control rate (250 Hz in SITL), stamped with that
clock. Where to wait is `sitl.firmware.px4_lockstep`'s (learn the cadence from the answers'
stamps, step on the sensor clock up to the sample an answer is due at, wait there). This loop
paces by the wall clock until the cadence is learned (one IMU sample per IMU period, as Gazebo
does), steps one sample past an answer due after GRACE_S (`grace_steps`), and after
ANSWER_TIMEOUT_S says so in one line on stderr and goes back to the wall-clock pace
(`answer_waits`, `stall_reports`). An answer stamped before the latest accepted one, or a
second with its stamp, is counted and ignored; one stamped before the latest sample applies
from the next step (`AnswerSchedule.late_answers`). Answers without the lockstep flag (PX4 on
the wall clock) set the held command and the plant keeps the wall-clock pace.

Bad input, never a crash: bytes that are no MAVLink frame are counted and skipped; other
messages are ignored (HEARTBEAT counted); an answer from another system id is ignored; a
motor output that is not finite stops its rotor (counted). A firmware that disconnects
leaves the world standing (no time passes, rotors commanded to zero) until one connects
again, which starts over from the wall-clock pace with the world as it stood.
"""

from __future__ import annotations

import math
import select
import time
from pathlib import Path
from typing import Any

from common.config.scenario import ConfigError, Scenario
from common.config.sensors import (
    PROFILE_IMU_RATE_MIN_HZ,
    period_us,
)
from common.links import LinkError, TcpServerLink, parse_url
from common.process.diagnostics import get_logger
from common.wire.mavlink import MAV, encoder, pack, parser
from common.wire.mission_items import PX4_SITL_HOME, HomePosition
from common.wire.simlink import (
    HIL_ACTUATOR_CONTROLS_ID,
    FrameReader,
    HilSensor,
    pack_hil_sensor,
    pack_odometry,
    unpack_actuator_controls,
)
from sitl.actuator_faults import ActuatorFaults
from sitl.firmware.px4_lockstep import Answer, AnswerSchedule, Wait
from sitl.firmware.px4_profile import physics_step_us, px4_sensor_profile, stale_warning
from sitl.firmware.px4_wire import (
    LOCKSTEP_FLAG,
    MODE_ARMED,
    command_from_outputs,
    gps_fields,
    motor_order,
    state_fields,
)
from sitl.plant import ActuatorCommand, PlantState, initial_state, scenario_plant
from sitl.sensor_feed import SensorFeed
from sitl.sensors import GpsModel
from sitl.server import LOG_BATCH, SITL_COMPONENT
from sitl.truth_log import TruthLog, flushed
from sitl.world import start_flight

log = get_logger(__name__)
GPS_HZ = 5.0  # PX4's Gazebo GPS plugin
STATE_DEFAULT_US = 5000  # HIL_STATE_QUATERNION: what PX4 asks on connecting (200 Hz)
MAX_LAG_S = 0.05  # wall-clock pace: further behind than this, resume from now
ANSWER_TIMEOUT_S = 1.0  # Gazebo's poll timeout: an answer due this long is given up
GRACE_S = 0.05  # an answer due this long: step one sample on and wait there (step_past)
POLL_S = 0.1


class Server:
    """The plant behind PX4's simulator MAVLink API; physics in `Plant`, samples in
    `SensorFeed`, the wire in `sitl.firmware.px4_wire`."""

    def __init__(self, scenario: Scenario, link_url: str, *, truth_log: Path | None,
                 end_time_s: float | None, system_id: int, home: HomePosition = PX4_SITL_HOME,
                 speed_factor: float | None = None) -> None:
        url = parse_url(link_url)
        if url.scheme != "tcpin":
            raise LinkError(f"--link {link_url}: PX4's simulator interface connects over TCP "
                            "to the plant: expected tcpin:HOST:PORT")
        self.scenario = scenario
        vehicle = scenario.vehicle
        self.order = motor_order(vehicle)
        self.w_max = vehicle.rotor_speed_max_rad_s
        profile = px4_sensor_profile(scenario)
        imu_period = period_us(profile.imu.rate_hz)
        if imu_period.denominator != 1:
            raise ConfigError(f"{profile.source or profile.name}: imu.rate_hz = "
                              f"{profile.imu.rate_hz:g}: PX4's clock comes from the IMU's "
                              "stamps, which need a whole number of microseconds apart")
        self.imu_us = int(imu_period)
        dt_us = physics_step_us(self.imu_us, scenario.physics_rate_hz)
        self.plant = scenario_plant(scenario, dt_us)
        self.substeps = self.imu_us // dt_us
        self.state: PlantState = initial_state(scenario, self.plant)
        self.faults = ActuatorFaults(scenario.actuator_faults)
        self.home = home
        self.feed = SensorFeed(profile, scenario.seed, self.plant, self.imu_us, home.alt_m,
                               imu_rate_min_hz=PROFILE_IMU_RATE_MIN_HZ)
        self.gps = GpsModel(profile.gps, scenario.seed)
        self.profile = profile
        self.warning = stale_warning(profile)
        if self.warning is not None:
            log.warning(self.warning)
        self.schedule = AnswerSchedule(self.imu_us)
        self.send_mocap = scenario.sensors is not None
        self.system_id = system_id
        self.link = TcpServerLink(url, max_clients=1)
        self.reader = FrameReader(True)
        self.mav = encoder(system_id, SITL_COMPONENT)
        self.decoder = parser()
        self.log = TruthLog(truth_log, scenario.name) if truth_log else None
        self._unflushed = 0
        self.duration_us = None if end_time_s is None else round(end_time_s * 1e6)
        self.end_us: int | None = None
        self.running = True
        # link and lockstep state
        self.client = False
        self.heard = False  # the firmware has spoken on this connection
        self.locked = False  # a lockstep answer has come
        self.command = ActuatorCommand((0.0,) * vehicle.n_rotors, (0.0,) * vehicle.n_rotors)
        self.sent_us = -1  # the latest HIL_SENSOR's time
        self.due_s = 0.0  # wall-clock pace: when the next step is due
        self.speed_factor = speed_factor  # lockstep paced at this x the wall clock, or free
        self.pace_due_s = 0.0  # paced lockstep: when the next step is due
        self._stalled = False  # an answer due timed out since the latest one on time
        self.flight_start_us: int | None = None
        self.state_interval_us = STATE_DEFAULT_US
        self.next_state_us = 0
        self.gps_us = round(1e6 / GPS_HZ)
        self.next_gps_us = 0
        self.started = False
        # statistics
        self.counts = dict.fromkeys(("hil_sensor", "hil_gps", "hil_state_quaternion",
                                     "odometry", "command_ack"), 0)
        self.steps = 0  # lockstep steps (on the sensor clock, the answer period known)
        self.paced_steps = 0  # steps on the wall clock (before the period is known)
        self.answers = 0
        self.stale_answers = 0
        self.extra_answers = 0
        self.time_mismatches = 0  # accepted answers stamped later than their sample
        self.ignored_answers = 0  # from another system id
        self.nonfinite_outputs = 0
        self.heartbeats = 0
        self.other_messages = 0
        self.rejected_bytes = 0
        self.connects = 0
        self.disconnects = 0
        self.answer_waits = 0  # answers due that did not come within ANSWER_TIMEOUT_S
        self.stall_reports = 0  # lines printed (one per run of such timeouts)
        self.grace_steps = 0  # steps taken past an answer due within GRACE_S (step_past)
        self.locked_wall_s = 0.0
        self.locked_sim_us = 0

    # ------------------------------------------------------------------ messages

    def _seq(self) -> int:
        seq = int(self.mav.seq)
        self.mav.seq = (seq + 1) % 256
        return seq

    def _messages(self, states: list[PlantState]) -> bytes:
        """The wire's messages for these physics steps (the last ends an IMU period): the
        GPS fix and the ground truth due, the motion-capture poses delivered, then the IMU
        sample (PX4 has the rest when the sample starts its step)."""
        s = states[-1]
        t = s.time_us
        lead = []
        samples = self.feed.period(states)
        if t >= self.next_gps_us:
            p, v = self.gps.sample(s.p_enu_m, s.v_enu_m_s)
            g = gps_fields(s._replace(p_enu_m=p, v_enu_m_s=v), self.home, self.profile.gps)
            lead.append(pack(self.mav, MAV.MAVLink_hil_gps_message(
                g.time_usec, g.fix_type, g.lat, g.lon, g.alt, g.eph, g.epv, g.vel, g.vn, g.ve,
                g.vd, g.cog, g.satellites_visible, 0, 0)))
            self.counts["hil_gps"] += 1
            while self.next_gps_us <= t:
                self.next_gps_us += self.gps_us
        if self.state_interval_us > 0 and t >= self.next_state_us:
            h = state_fields(s, self.home, self.feed.true_f_flu_m_s2)
            lead.append(pack(self.mav, MAV.MAVLink_hil_state_quaternion_message(*h)))
            self.counts["hil_state_quaternion"] += 1
            while self.next_state_us <= t:
                self.next_state_us += self.state_interval_us
        imu = []
        for m in samples:
            if isinstance(m, HilSensor):
                imu.append(pack_hil_sensor(m, self._seq(), self.system_id, SITL_COMPONENT))
                self.counts["hil_sensor"] += 1
                self.sent_us = m.time_usec
            elif self.send_mocap:
                lead.append(pack_odometry(m, self._seq(), self.system_id, SITL_COMPONENT))
                self.counts["odometry"] += 1
        return b"".join(lead + imu)

    def _heard(self) -> None:
        """Bytes from the firmware: the first on a connection start the samples (PX4 sends
        its HEARTBEAT first "to initiate the SITL simulator to start sending sensor
        data"), the first ever the clock of `end_time_s`."""
        if not self.heard:
            self.heard = True
            self.due_s = time.monotonic()
        if self.end_us is None and self.duration_us is not None:
            self.end_us = self.state.time_us + self.duration_us

    def _receive(self) -> None:
        for peer, data in self.link.recv():
            self._heard()
            frames, rejected = self.reader.feed(peer, data)
            self.rejected_bytes += rejected
            for f in frames:
                if f.msg_id == HIL_ACTUATOR_CONTROLS_ID:
                    if f.sysid != self.system_id:
                        self.ignored_answers += 1
                    else:
                        a = unpack_actuator_controls(f.payload)
                        self._on_controls(a.time_usec, a.controls, a.mode, a.flags)
                else:
                    self._on_other(f.raw)

    def _on_other(self, raw: bytes) -> None:
        try:
            msgs = self.decoder.parse_buffer(raw) or []
        except Exception:  # pymavlink raises its own errors on what it cannot decode
            msgs = []
        for msg in msgs:
            kind = msg.get_type()
            if kind == "HEARTBEAT":
                self.heartbeats += 1
            elif kind == "COMMAND_LONG" and msg.command == MAV.MAV_CMD_SET_MESSAGE_INTERVAL \
                    and msg.target_system in (0, self.system_id):
                self._set_interval(msg)
            else:
                self.other_messages += 1

    def _set_interval(self, msg: Any) -> None:
        """SET_MESSAGE_INTERVAL: HIL_STATE_QUATERNION's interval (param2 us, -1 off, 0
        default); any other message's is UNSUPPORTED."""
        result = MAV.MAV_RESULT_UNSUPPORTED
        interval = msg.param2
        if round(msg.param1) == MAV.MAVLINK_MSG_ID_HIL_STATE_QUATERNION and \
                math.isfinite(interval):
            if interval < 0:
                self.state_interval_us = 0
            else:
                self.state_interval_us = round(interval) or STATE_DEFAULT_US
                self.next_state_us = self.state.time_us
            result = MAV.MAV_RESULT_ACCEPTED
        self.link.send(pack(self.mav, MAV.MAVLink_command_ack_message(
            MAV.MAV_CMD_SET_MESSAGE_INTERVAL, result, 0, 0, 0, 0)))
        self.counts["command_ack"] += 1

    def _on_controls(self, time_usec: int, controls: tuple[float, ...], mode: int,
                     flags: int) -> None:
        self.answers += 1
        cmd = command_from_outputs(controls, mode, self.order, self.w_max)
        self.nonfinite_outputs += cmd.nonfinite
        if flags & LOCKSTEP_FLAG:
            self.locked = True  # from the first lockstep answer on, as Gazebo does
            kind = self.schedule.accept(time_usec, self.sent_us)  # late: counted there
            if kind is Answer.STALE:
                self.stale_answers += 1  # before the latest accepted answer
                return
            if kind is Answer.EXTRA:
                self.extra_answers += 1  # that sample has its answer already
                return
            if time_usec > self.sent_us:
                self.time_mismatches += 1
        else:
            self.locked = False
        self.command = cmd.command
        if mode & MODE_ARMED and self.flight_start_us is None:
            self.flight_start_us = self.state.time_us
            start_flight(self.scenario, self.plant, self.faults, self.feed, self.state.time_us)

    # ------------------------------------------------------------------ stepping

    def _step(self) -> None:
        """One IMU period of physics under the held command, then its messages."""
        states = []
        for _ in range(self.substeps):
            self.state = self.plant.step(self.state, self.faults.apply(self.command,
                                                                        self.state))
            states.append(self.state)
        self.link.send(self._messages(states))
        if self.log is not None:
            self.log.record(self.state)
            self._unflushed += 1
            if self._unflushed >= LOG_BATCH:
                self._flush_log()

    def _flush_log(self) -> None:
        self._unflushed = 0
        self.log = flushed(self.log, self.state.time_us)

    def _connected(self) -> None:
        self.client = True
        self.connects += 1
        self.reader = FrameReader(True)
        self.decoder = parser()
        self.locked = False
        self.schedule.reset()
        self.due_s = time.monotonic()
        if not self.started:
            self.started = True
            if self.log is not None:
                self.log.record(self.state)

    def _disconnected(self) -> None:
        self.client = False
        self.heard = False
        self.disconnects += 1
        self.locked = False
        self.schedule.reset()
        n = self.scenario.vehicle.n_rotors
        self.command = ActuatorCommand((0.0,) * n, (0.0,) * n)  # the firmware is gone
        self._flush_log()

    def _at_end(self) -> bool:
        return self.end_us is not None and self.state.time_us >= self.end_us

    def run(self) -> None:
        try:
            self._loop()
        finally:
            self.close()

    def _loop(self) -> None:
        link = self.link
        imu_s = self.imu_us * 1e-6
        last_step_s: float | None = None  # wall time of the latest lockstep step
        while self.running and not self._at_end():
            if not link.clients:
                if self.client:
                    self._disconnected()
                    last_step_s = None
                select.select([link.fileno()], [], [], POLL_S)
                self._receive()  # accepts a connection
                continue
            if not self.client:
                self._connected()
            if not self.heard:  # samples start when the firmware speaks
                if select.select(link.filenos(), [], [], POLL_S)[0]:
                    self._receive()
                continue
            if not (self.locked and self.schedule.learned):  # the wall-clock pace
                last_step_s = None
                self._paced_step(imu_s)
                continue
            if select.select(link.filenos(), [], [], 0.0)[0]:
                self._receive()  # what came meanwhile, without waiting
                continue
            if self._awaiting_answer() or self._pace_wait(imu_s):
                continue
            self._step()
            self.steps += 1
            now = time.monotonic()
            if last_step_s is not None:
                self.locked_wall_s += now - last_step_s
                self.locked_sim_us += self.imu_us
            last_step_s = now
        self._flush_log()

    def _paced_step(self, imu_s: float) -> None:
        """Before the lockstep holds: a step once due on the wall clock; until then, a wait."""
        wait = self.due_s - time.monotonic()
        if wait > 0.0:
            if select.select(self.link.filenos(), [], [], wait)[0]:
                self._receive()
            return
        if -wait > MAX_LAG_S:
            self.due_s = time.monotonic()
        self._step()
        self.paced_steps += 1
        self.due_s += imu_s

    def _awaiting_answer(self) -> bool:
        """In lockstep: whether the plant still waits for the answer due (having waited
        briefly for what arrives); False once it may step (`AnswerSchedule.wait_at`: no
        answer due, GRACE_S passed, or ANSWER_TIMEOUT_S since the wait began)."""
        schedule = self.schedule
        # what came is read before deciding: a plant starved past the grace or the timeout
        # steps past or gives up on no answer that came meanwhile
        if schedule.last_us != self.sent_us and schedule.waits_at(self.sent_us) and \
                select.select(self.link.filenos(), [], [], 0.0)[0]:
            self._receive()
        if schedule.last_us == self.sent_us:
            self._stalled = False
        every = schedule.longest or 0
        now = time.monotonic()
        wait, until_s = schedule.wait_at(self.sent_us, now, GRACE_S, ANSWER_TIMEOUT_S)
        if wait is Wait.WAIT:
            if select.select(self.link.filenos(), [], [], until_s - now)[0]:
                self._receive()
            return True
        if wait is Wait.STEP_PAST:
            self.grace_steps += 1
        elif wait is Wait.GIVE_UP:
            self._give_up(every)
        return False

    def _give_up(self, every: int) -> None:
        """The answer due did not come within ANSWER_TIMEOUT_S (`every` samples after the
        one before): as Gazebo's poll timeout, step on without it, on the wall clock until
        the cadence is learned again; said once per run of such timeouts."""
        self.answer_waits += 1
        if self._stalled:
            return
        self._stalled = True
        self.stall_reports += 1
        self._flush_log()
        log.warning("sitl: no answer to the sample at t = %.3f s within %g s (the firmware "
                    "answers every %s samples, %s us): advancing without it, on the wall clock "
                    "until it answers again", self.sent_us * 1e-6, ANSWER_TIMEOUT_S, every,
                    every * self.imu_us)

    def _pace_wait(self, imu_s: float) -> bool:
        """With `speed_factor`: whether the next lockstep step is not yet due on the wall
        clock (no faster than X x real time; then waited for, briefly, taking in what
        arrives); False once it is due, with the step after it scheduled."""
        if self.speed_factor is None:
            return False
        wait = self.pace_due_s - time.monotonic()
        if wait > 0.0:
            if select.select(self.link.filenos(), [], [], wait)[0]:
                self._receive()
            return True
        self.pace_due_s = max(self.pace_due_s, time.monotonic() - MAX_LAG_S) + \
            imu_s / self.speed_factor
        return False

    # ------------------------------------------------------------------ results

    def stats(self) -> dict[str, Any]:
        wall = self.locked_wall_s
        return {"protocol": "px4-hil", "imu_hz": self.profile.imu.rate_hz,
                "baro_hz": self.profile.baro.rate_hz, "mag_hz": self.profile.mag.rate_hz,
                "gps_hz": GPS_HZ, "physics_dt_us": self.plant.dt_us,
                "motor_order": list(self.order),
                "sim_time_s": self.state.time_us * 1e-6, "steps": self.steps,
                "paced_steps": self.paced_steps, "sent": dict(self.counts),
                "answers": self.answers, "stale_answers": self.stale_answers,
                "extra_answers": self.extra_answers, "time_mismatches": self.time_mismatches,
                "ignored_answers": self.ignored_answers,
                "nonfinite_outputs": self.nonfinite_outputs, "heartbeats": self.heartbeats,
                "other_messages": self.other_messages, "rejected_bytes": self.rejected_bytes,
                "connects": self.connects, "disconnects": self.disconnects,
                "refused_clients": self.link.refused_clients,
                "answer_waits": self.answer_waits, "stall_reports": self.stall_reports,
                "grace_steps": self.grace_steps, **self.schedule.stats(),
                "grace_s": min(GRACE_S * self.schedule.grace_scale, 0.5 * ANSWER_TIMEOUT_S),
                "speed_factor": self.speed_factor,
                "state_interval_us": self.state_interval_us,
                "lockstep_wall_s": wall,
                "real_time_factor": self.locked_sim_us * 1e-6 / wall if wall > 0 else None}

    def summary(self) -> str:
        return (f"stopped at t = {self.state.time_us * 1e-6:.3f} s after {self.steps} lockstep "
                f"steps ({self.paced_steps} on the wall clock before the firmware answered); "
                f"{self.answers} answers, {self.stale_answers + self.extra_answers} ignored, "
                f"{self.rejected_bytes} bytes rejected, {self.disconnects} disconnects")

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
            self.log = None
        self.link.close()
