"""The plant as a simulator link server, like PX4's simulator interface (`sitl` with the
dqflight protocol; the command line is `sitl.node`).

Lockstep (default): the plant sends ODOMETRY (and HIL_SENSOR at its own rate) stamped with
simulated time and advances one control period only when a HIL_ACTUATOR_CONTROLS answers that
state (`time_usec` echoed); duplicates and stale answers are ignored, and a state that stays
unanswered is re-sent after a few milliseconds of wall time, so loss delays but never
deadlocks. Simulated time therefore stands still until the FCU starts answering (when the
flight starts).

With a sensor profile (`--sensors`, docs/simulator-link.md#sensors) the FCU gets what a real vehicle
gets instead of the exact state: HIL_SENSOR per IMU sample (the one at the end of each
control period drives the lockstep) and the motion-capture pose as ODOMETRY after its
latency (sitl/sensor_feed.py); the exact state goes only to the truth log. Its estimator
aligns on the ground before it may arm: the FCU answers those periods disarmed, and the
world stands still (time and sensors run) until the first armed answer, the flight's start,
from which the scenario's clock (disturbances, duration) counts (`sitl.world`).

Lockstep paced (`--speed-factor X`): the same exchange, each state sent no sooner than X
times real time allows (simulated time at most X times the wall clock's pace): for a person
or a script at a ground station, with the results of lockstep.

Real time (`--realtime`): physics paced by the monotonic clock, the latest command held; a
process stopped or starved for longer than MAX_LAG_S resumes from where it stood instead of
replaying the missed wall time in a burst. With a sensor profile each sample goes out as it
falls due; the world does not stand still before the flight.

The ground-truth log (one row per state sent) is the run's reference for every metric.
"""

from __future__ import annotations

import os
import select
import time
from pathlib import Path
from typing import Any

from common.config.scenario import ConfigError, Scenario
from common.config.sensors import SensorProfile
from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.links import RECV_BATCH, open_link
from common.process.startup import compile_time_s
from common.wire.mavlink import MAV
from common.wire.simlink import (
    HIL_ACTUATOR_CONTROLS_ID,
    TIMESYNC_ID,
    FrameReader,
    HilSensor,
    Odometry,
    pack_hil_sensor,
    pack_odometry,
    pack_timesync,
    unpack_actuator_controls,
    unpack_timesync,
)
from sitl.plant import ActuatorCommand, PlantState, rotate_inv
from sitl.sensor_feed import pressure_hpa
from sitl.truth_log import TruthLog, flushed
from sitl.world import World, command_from_controls

SITL_COMPONENT = MAV.MAV_COMP_ID_PERIPHERAL
SPIN_S = 0.002  # lockstep: poll instead of sleeping this long after each exchange
MAX_LAG_S = 0.05  # real time: further behind the wall clock than this, skip ahead
LOG_BATCH = 32  # lockstep: truth records handed to the kernel together (and when idle)
HIL_SENSOR_FIELDS = 0x1A3F  # acc, gyro, abs pressure, pressure altitude, temperature; no mag
# Per-step stages timed in lockstep flight (`stage_us` in the stats): waiting for the
# answer (the FCU's work and the transport), reading and parsing it, the plant, packing the
# state, sending it, the truth log.
STAGES = ("wait", "rx", "plant", "pack", "send", "log")


def odometry(s: PlantState) -> Odometry:
    """The state as ODOMETRY carries it: local NED, NED->FRD attitude, FRD twist."""
    return Odometry(s.time_us, enu_to_ned(s.p_enu_m), q_enu_flu_to_ned_frd(s.q_enu_flu),
                    flu_to_frd(rotate_inv(s.q_enu_flu, s.v_enu_m_s)),
                    flu_to_frd(s.omega_flu_rad_s))



class SimulatorServer:
    """The world behind a simulator link; I/O only, physics in `World`."""

    def __init__(self, scenario: Scenario, link_url: str, *, truth_log: Path | None,
                 end_time_s: float | None, realtime: bool, control_rate_hz: int,
                 hil_sensor_hz: float, resend_ms: float, system_id: int,
                 home_alt_m: float = 0.0, sensors: SensorProfile | None = None,
                 seed: int = 0, speed_factor: float | None = None) -> None:
        self.scenario = scenario
        self.control_dt_us = 1_000_000 // control_rate_hz
        self.world = World(scenario, self.control_dt_us, sensors=sensors, seed=seed,
                           home_alt_m=home_alt_m)
        self.plant = self.world.plant
        if self.control_dt_us % self.plant.dt_us:
            raise ConfigError(f"control period {self.control_dt_us} us is not a multiple of "
                              f"the physics step {self.plant.dt_us} us")
        self.substeps = self.world.substeps
        self.link = open_link(link_url, role="sim_server", system_id=system_id)
        self.reader = FrameReader(self.link.is_stream)
        self.realtime = realtime
        self.duration_us = None if end_time_s is None else round(end_time_s * 1e6)
        self.end_us: int | None = None
        self.feed = self.world.feed
        self.sensor_every = (max(1, round(control_rate_hz / hil_sensor_hz))
                             if hil_sensor_hz > 0 else 0)
        self.resend_s = resend_ms * 1e-3
        self.home_alt_m = home_alt_m
        self.system_id = system_id
        self.seq = 0
        self.log = TruthLog(truth_log, scenario.name) if truth_log else None
        self.command = ActuatorCommand(self.state.rotor_speed_rad_s, self.state.tilt_rad)
        self.steps = 0
        self.ignored_answers = 0
        self.rejected_bytes = 0
        self.resends = 0
        self.timesync_answers = 0  # TIMESYNC requests answered (the FCU's round-trip probe)
        self.stage_ns = dict.fromkeys(STAGES, 0)
        self.timed_steps = 0
        self._unflushed = 0
        self.skipped_s = 0.0  # real time: wall time not simulated (the process was stopped)
        self.speed_factor = speed_factor  # lockstep paced at this x the wall clock, or free
        self.pace_due_s = 0.0  # paced: when the next state may go out (monotonic)
        self.running = True
        self._last_datagram = b""

    @property
    def state(self) -> PlantState:
        """The world's state: the latest sent (lockstep) or stepped (real time)."""
        return self.world.state

    @property
    def flight_start_us(self) -> int | None:
        """The flight's start (the first armed answer): the scenario's clock counts from it."""
        return self.world.flight_start_us

    # ------------------------------------------------------------------ messages

    def _datagram(self, states: list[PlantState]) -> bytes:
        """A control period's messages: the exact state (truth), or the sensors' samples."""
        s = states[-1]
        if self.feed is not None:
            parts: list[bytes] = []
            for m in self.feed.period(states):
                self.seq = (self.seq + 1) & 0xFF
                parts.append(pack_hil_sensor(m, self.seq, self.system_id, SITL_COMPONENT)
                             if isinstance(m, HilSensor) else
                             pack_odometry(m, self.seq, self.system_id, SITL_COMPONENT))
            return b"".join(parts)
        self.seq = (self.seq + 1) & 0xFF
        data = pack_odometry(odometry(s), self.seq, self.system_id, SITL_COMPONENT)
        if self.sensor_every and (s.time_us // self.control_dt_us) % self.sensor_every == 0:
            data = self._hil_sensor(s) + data
        return data

    def _hil_sensor(self, s: PlantState) -> bytes:
        """The exact state's HIL_SENSOR; the specific force holds the ground contact's
        impulse since the previous one, spread over the interval between them."""
        interval_s = self.sensor_every * self.control_dt_us * 1e-6
        acc = flu_to_frd(self.plant.specific_force_flu(
            s, contact_dv_enu=self.world.take_contact_dv(), interval_s=interval_s))
        gyro = flu_to_frd(s.omega_flu_rad_s)
        alt = self.home_alt_m + s.p_enu_m[2]
        self.seq = (self.seq + 1) & 0xFF
        return pack_hil_sensor(HilSensor(s.time_us, acc, gyro, (0.0, 0.0, 0.0),
                                         pressure_hpa(alt), alt, 15.0, HIL_SENSOR_FIELDS),
                               self.seq, self.system_id, SITL_COMPONENT)

    def _send_state(self, states: list[PlantState] | None = None, *, batch: bool = False,
                    timed: bool = False) -> None:
        """Send the state of a control period and log it; with `batch` (lockstep) the truth
        records reach the kernel LOG_BATCH at a time, and whenever the loop goes idle.
        `timed`: add the stages' times to `stage_ns`."""
        t0 = time.perf_counter_ns() if timed else 0
        self._last_datagram = self._datagram(states or [self.state])
        t1 = time.perf_counter_ns() if timed else 0
        self.link.send(self._last_datagram)
        t2 = time.perf_counter_ns() if timed else 0
        if self.log is not None:
            self.log.record(self.state)
            self._unflushed += 1
            if not batch or self._unflushed >= LOG_BATCH:
                self._flush_log()
        if timed:
            t3 = time.perf_counter_ns()
            ns = self.stage_ns
            ns["pack"] += t1 - t0
            ns["send"] += t2 - t1
            ns["log"] += t3 - t2

    def _flush_log(self) -> None:
        self._unflushed = 0
        self.log = flushed(self.log, self.state.time_us)

    def _command_from(self, controls: tuple[float, ...], mode: int) -> ActuatorCommand:
        return command_from_controls(controls, mode, self.scenario.vehicle, self.state)

    def _on_answer(self, armed: bool) -> None:
        """An answer to the latest state: the first armed one starts the flight."""
        if armed and self.flight_start_us is None:
            self.world.start_flight()
            if self.duration_us is not None:
                self.end_us = self.state.time_us + self.duration_us

    def _advance(self) -> list[PlantState]:
        """One control period (`World.advance`: before the flight the world stands still)."""
        states = self.world.advance(self.command)
        self.steps += 1
        return states

    def _answers(self, limit: int = RECV_BATCH) -> list[tuple[int, tuple[float, ...], int]]:
        out: list[tuple[int, tuple[float, ...], int]] = []
        for peer, data in self.link.recv(limit):
            frames, rejected = self.reader.feed(peer, data)
            self.rejected_bytes += rejected
            for f in frames:
                if f.msg_id == HIL_ACTUATOR_CONTROLS_ID and f.sysid != self.system_id:
                    self.ignored_answers += 1  # another system's FCU: not ours to obey
                elif f.msg_id == HIL_ACTUATOR_CONTROLS_ID:
                    a = unpack_actuator_controls(f.payload)
                    out.append((a.time_usec, a.controls, a.mode))
                elif f.msg_id == TIMESYNC_ID:
                    self._timesync(f.payload)
        return out

    def _timesync(self, payload: bytes) -> None:
        """Answer a TIMESYNC request (tc1 = 0) at once: tc1 = our monotonic clock in ns,
        ts1 echoed; answers (tc1 != 0) are not ours to take. The FCU times its round trips
        with these (`udp_rtt_us`), so nothing else is done for them."""
        tc1, ts1 = unpack_timesync(payload)
        if tc1 != 0:
            return
        self.seq = (self.seq + 1) & 0xFF
        self.link.send(pack_timesync(time.monotonic_ns() or 1, ts1, self.seq, self.system_id,
                                     SITL_COMPONENT))
        self.timesync_answers += 1

    # ------------------------------------------------------------------ loops

    def run(self) -> None:
        try:
            if self.realtime:
                self._run_realtime()
            else:
                self._run_lockstep()
        finally:
            self.close()

    def _at_end(self) -> bool:
        if self.realtime:
            return self.duration_us is not None and self.state.time_us >= self.duration_us
        return self.end_us is not None and self.state.time_us >= self.end_us

    def _run_lockstep(self) -> None:
        self._send_state()
        link = self.link
        spin = link.spin
        fds = link.filenos()
        last_progress = time.monotonic()
        last_resend = last_progress
        sent_ns = time.perf_counter_ns()
        ns = self.stage_ns
        perf = time.perf_counter_ns
        while self.running:
            now = time.monotonic()
            idle = now - last_progress
            spinning = spin and idle < SPIN_S
            if spinning:  # the answer is microseconds away: poll for it
                if not select.select(fds, [], [], 0.0)[0]:
                    os.sched_yield()  # let a process that has work run on this core
                    continue
            else:
                if self._unflushed:
                    self._flush_log()  # idle: what is logged reaches the file
                wait = self.resend_s if idle < 0.5 else 0.05
                since = now - max(last_resend, last_progress)
                fds = link.filenos()
                if not select.select(fds, [], [], max(0.0, wait - since))[0]:
                    if time.monotonic() - max(last_resend, last_progress) >= wait:
                        link.send(self._last_datagram)  # recover a lost state or answer
                        self.resends += 1
                        last_resend = time.monotonic()
                    continue
            rx_ns = perf()
            answers = self._answers(1 if spinning else RECV_BATCH)
            parsed_ns = perf()
            for time_usec, controls, mode in answers:
                if time_usec != self.state.time_us or self._at_end():
                    self.ignored_answers += 1  # duplicate, stale, or the run has ended
                    continue
                timed = self.flight_start_us is not None  # in flight before this answer
                self._on_answer(bool(mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED))
                self.command = self._command_from(controls, mode)
                t0 = perf()
                states = self._advance()
                if timed:
                    ns["wait"] += rx_ns - sent_ns
                    ns["rx"] += parsed_ns - rx_ns
                    ns["plant"] += perf() - t0
                    self.timed_steps += 1
                self._pace()  # not in the plant's time: it waits for the wall clock
                self._send_state(states, batch=True, timed=timed)
                sent_ns = perf()
                last_progress = time.monotonic()
            fds = link.filenos()

    def _pace(self) -> None:
        """With `speed_factor`: wait until the next state is due, no faster than X times the
        wall clock (a process starved for longer than MAX_LAG_S goes on from now instead of
        catching up in a burst). Nothing else is waited for meanwhile: in lockstep the FCU
        is waiting for this state."""
        if self.speed_factor is None:
            return
        now = time.monotonic()
        self.pace_due_s = max(self.pace_due_s, now - MAX_LAG_S) + \
            self.control_dt_us * 1e-6 / self.speed_factor
        if self.pace_due_s > now:
            time.sleep(self.pace_due_s - now)

    def _run_realtime(self) -> None:
        period = self.plant.dt_us * 1e-6
        start = time.monotonic()
        self._send_state()
        physics_steps = 0
        while self.running and not self._at_end():
            due = start + (physics_steps + 1) * period
            behind = time.monotonic() - due
            if behind > MAX_LAG_S:
                start += behind
                due += behind
                self._skip(behind)
            self._answers_until(due)
            self.world.physics_step(self.command)
            physics_steps += 1
            self._after_physics_step(physics_steps)
        while self.running:  # the run has ended: keep the link quiet until told to stop
            select.select(self.link.filenos(), [], [], 0.1)
            self._answers()

    def _skip(self, behind: float) -> None:
        """The process was stopped or starved: the world stood still with it. It resumes
        from now instead of replaying the missed time in a burst (with commands that
        arrived after it), which would hide the stall from the records: counted, logged."""
        self.skipped_s += behind
        if self.log is not None:
            self.log.log(self.state.time_us, MAV.MAV_SEVERITY_WARNING,
                          f"simulator stalled {behind:.3f} s: resumed from here")

    def _answers_until(self, due: float) -> None:
        """Take the FCU's answers (its commands) until the wall clock reaches `due`."""
        while self.running:
            wait = due - time.monotonic()
            readable, _, _ = select.select(self.link.filenos(), [], [], max(0.0, wait))
            if readable:
                for _t, controls, mode in self._answers():
                    self._on_answer(bool(mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED))
                    self.command = self._command_from(controls, mode)
            if wait <= 0.0:
                break

    def _after_physics_step(self, physics_steps: int) -> None:
        """A sensor profile's samples sent as they are due; each control period, the state
        sent (the truth profile) or the truth recorded."""
        if self.feed is not None:  # every sample as it is due, not once a period
            data = self._datagram([self.state])
            if data:
                self.link.send(data)
        if physics_steps % self.substeps == 0:
            self.steps += 1
            if self.feed is None:
                self._send_state()
            elif self.log is not None:
                self.log.record(self.state)
                self.log.flush()

    def stats(self) -> dict[str, Any]:
        n = max(self.timed_steps, 1)
        return {"steps": self.steps, "resends": self.resends,
                "compile_time_s": compile_time_s(),
                "ignored_answers": self.ignored_answers,
                "rejected_bytes": self.rejected_bytes,
                "timesync_answers": self.timesync_answers,
                "timed_steps": self.timed_steps,
                "stage_us": {k: v / n * 1e-3 for k, v in self.stage_ns.items()}}

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
            self.log = None
        self.link.close()

