"""`sitl`: the plant as a process, serving a simulator link like PX4's simulator interface.

Lockstep (default): the plant sends ODOMETRY (and HIL_SENSOR at its own rate) stamped with
simulated time and advances one control period only when a HIL_ACTUATOR_CONTROLS answers that
state (`time_usec` echoed); duplicates and stale answers are ignored, and a state that stays
unanswered is re-sent after a few milliseconds of wall time, so loss delays but never
deadlocks. Simulated time therefore stands still until the FCU starts answering (when the
flight starts).

With a sensor profile (`--sensors`, DESIGN.md section 3) the FCU gets what a real vehicle
gets instead of the exact state: HIL_SENSOR per IMU sample (the one at the end of each
control period drives the lockstep) and the motion-capture pose as ODOMETRY after its
latency (sitl/sensor_feed.py); the exact state goes only to the truth log. Its estimator
aligns on the ground before it may arm: the FCU answers those periods disarmed, and the
world stands still (time and sensors run) until the first armed answer, the flight's start,
from which the scenario's clock (disturbances, duration) counts.

Real time (`--realtime`): physics paced by the monotonic clock, the latest command held; a
process stopped or starved for longer than MAX_LAG_S resumes from where it stood instead of
replaying the missed wall time in a burst. With a sensor profile each sample goes out as it
falls due; the world does not stand still before the flight.

The ground-truth log (one row per state sent) is the run's reference for every metric.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import math
import os
import select
import signal
import sys
import time
from pathlib import Path
from typing import Any, Protocol

from common import startup
from common.cliargs import OneLineParser, check_output_path
from common.config import (
    ConfigError,
    Scenario,
    VehicleConfig,
    check_sensor_faults,
    load_scenario,
)
from common.frames import enu_to_ned, flu_to_frd, q_enu_flu_to_ned_frd
from common.jit import compile_time_s
from common.links import RECV_BATCH, LinkError, open_link, parse_url
from common.mavlink import MAV
from common.parent import stop_with_parent
from common.sensors_config import SensorProfile, resolve_sensor_profile
from common.simlink import (
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
from common.ulog import ULogError
from sitl.actuator_faults import ActuatorFaults
from sitl.plant import (
    ActuatorCommand,
    Plant,
    PlantState,
    initial_state,
    rotate_inv,
    scenario_plant,
)
from sitl.sensor_feed import SensorFeed, pressure_hpa
from sitl.truth_log import TruthLog

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


def command_from_controls(controls: tuple[float, ...], mode: int, vehicle: VehicleConfig,
                          state: PlantState) -> ActuatorCommand:
    """HIL_ACTUATOR_CONTROLS as the plant obeys it: controls[0..n) x w_max rotor speeds
    (zero unless SAFETY_ARMED), controls[n..2n) tilts; a value that is not finite means
    zero speed or the current tilt."""
    n = vehicle.n_rotors
    isfinite = math.isfinite
    if mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED:
        w_max = vehicle.rotor_speed_max_rad_s
        speeds = tuple([c * w_max if isfinite(c) else 0.0 for c in controls[:n]])
    else:
        speeds = (0.0,) * n
    tilts = controls[n:2 * n]
    if not isfinite(sum(tilts)):
        tilts = tuple([c if isfinite(c) else t for c, t in zip(tilts, state.tilt_rad, strict=True)])
    return ActuatorCommand(speeds, tuple(tilts))


def start_flight(scenario: Scenario, plant: Plant, faults: ActuatorFaults,
                 feed: SensorFeed | None, t_us: int) -> None:
    """The flight starts at t_us: the scenario's disturbances, actuator faults and sensor
    faults count from it."""
    plant.disturbance = plant.disturbance.from_time(t_us * 1e-6)
    faults.start_flight(t_us)
    if feed is not None:
        feed.start_flight(t_us, scenario.sensor_faults)


class SimulatorServer:
    """The plant behind a simulator link; I/O only, physics in `Plant`."""

    def __init__(self, scenario: Scenario, link_url: str, *, truth_log: Path | None,
                 end_time_s: float | None, realtime: bool, control_rate_hz: int,
                 hil_sensor_hz: float, resend_ms: float, system_id: int,
                 home_alt_m: float = 0.0, sensors: SensorProfile | None = None,
                 seed: int = 0) -> None:
        self.scenario = scenario
        self.plant = scenario_plant(scenario, 1_000_000 // scenario.physics_rate_hz)
        self.state = initial_state(scenario, self.plant)
        self.faults = ActuatorFaults(scenario.actuator_faults)
        self.control_dt_us = 1_000_000 // control_rate_hz
        if self.control_dt_us % self.plant.dt_us:
            raise ConfigError(f"control period {self.control_dt_us} us is not a multiple of "
                              f"the physics step {self.plant.dt_us} us")
        self.substeps = self.control_dt_us // self.plant.dt_us
        self.link = open_link(link_url, role="sim_server", system_id=system_id)
        self.reader = FrameReader(self.link.is_stream)
        self.realtime = realtime
        self.duration_us = None if end_time_s is None else round(end_time_s * 1e6)
        # The flight's start (the first armed answer): the scenario's clock counts from it.
        self.flight_start_us: int | None = None
        self.end_us: int | None = None
        self.feed = SensorFeed(sensors, seed, self.plant, self.control_dt_us, home_alt_m) \
            if sensors is not None and not sensors.is_truth else None
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
        self.running = True
        self._last_datagram = b""

    # ------------------------------------------------------------------ messages

    def _datagram(self, states: list[PlantState]) -> bytes:
        """A control period's messages: the exact state (truth), or the sensors' samples."""
        s = states[-1]
        if self.feed is not None:
            parts = []
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
        acc = flu_to_frd(self.plant.specific_force_flu(s))
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
        if self.log is None:
            return
        self._unflushed = 0
        self.log.flush()
        if self.log.failed:  # a full disk, an I/O error: the log ends, the world goes on
            print(f"sitl: truth log stopped at t = {self.state.time_us * 1e-6:.3f} s: "
                  f"{self.log.failed}", file=sys.stderr, flush=True)
            self.log.close()
            self.log = None

    def _command_from(self, controls: tuple[float, ...], mode: int) -> ActuatorCommand:
        return command_from_controls(controls, mode, self.scenario.vehicle, self.state)

    def _on_answer(self, armed: bool) -> None:
        """An answer to the latest state: the first armed one starts the flight."""
        if armed and self.flight_start_us is None:
            self.flight_start_us = self.state.time_us
            start_flight(self.scenario, self.plant, self.faults, self.feed, self.state.time_us)
            if self.duration_us is not None:
                self.end_us = self.state.time_us + self.duration_us

    def _advance(self) -> list[PlantState]:
        """One control period; before the flight starts the world stands still while time
        (and the sensors) run, so the estimator aligns on a vehicle at rest."""
        states = []
        for _ in range(self.substeps):
            if self.flight_start_us is None:
                self.state = self.state._replace(time_us=self.state.time_us + self.plant.dt_us)
            else:
                self.state = self.plant.step(self.state,
                                             self.faults.apply(self.command, self.state))
            states.append(self.state)
        self.steps += 1
        return states

    def _answers(self, limit: int = RECV_BATCH) -> list[tuple[int, tuple[float, ...], int]]:
        out = []
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
                self._send_state(states, batch=True, timed=timed)
                sent_ns = perf()
                last_progress = time.monotonic()
            fds = link.filenos()

    def _run_realtime(self) -> None:
        period = self.plant.dt_us * 1e-6
        start = time.monotonic()
        self._send_state()
        physics_steps = 0
        while self.running and not self._at_end():
            due = start + (physics_steps + 1) * period
            behind = time.monotonic() - due
            if behind > MAX_LAG_S:
                # The process was stopped or starved: the world stood still with it. Resume
                # from now instead of replaying the missed time in a burst (with commands
                # that arrived after it), which would hide the stall from the records.
                start += behind
                due += behind
                self.skipped_s += behind
                if self.log is not None:
                    self.log.log(self.state.time_us, MAV.MAV_SEVERITY_WARNING,
                                  f"simulator stalled {behind:.3f} s: resumed from here")
            while self.running:
                wait = due - time.monotonic()
                readable, _, _ = select.select(self.link.filenos(), [], [], max(0.0, wait))
                if readable:
                    for _t, controls, mode in self._answers():
                        self._on_answer(bool(mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED))
                        self.command = self._command_from(controls, mode)
                if wait <= 0.0:
                    break
            self.state = self.plant.step(self.state, self.faults.apply(self.command, self.state))
            physics_steps += 1
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
        while self.running:  # the run has ended: keep the link quiet until told to stop
            select.select(self.link.filenos(), [], [], 0.1)
            self._answers()

    def stats(self) -> dict:
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


# The simulator protocols `sitl` serves: its own link to this project's FCU, and the
# interfaces through which external physics engines serve real firmware. Each has its own
# default --link; with a firmware protocol the firmware drives simulated time.
DQFLIGHT = "dqflight"
DEFAULT_LINKS = {DQFLIGHT: "udpin:127.0.0.1:4560",  # this project's FCU (PX4's port)
                 "ardupilot-json": "udpin:127.0.0.1:9002",  # ArduPilot's SIM_JSON
                 "px4-hil": "tcpin:127.0.0.1:4560"}  # PX4's simulator MAVLink API
FIRMWARE_MODULES = {"ardupilot-json": "sitl.ardupilot_json", "px4-hil": "sitl.px4_hil"}
# Options that only the dqflight protocol takes (the firmware protocols refuse them): the
# firmware sets the rates and drives the clock.
DQFLIGHT_ONLY = ("realtime", "control_rate", "hil_sensor_hz", "resend_ms")


class FirmwareServer(Protocol):
    """What a firmware protocol's module provides as `Server(scenario, link_url, *,
    truth_log, end_time_s)`: the plant behind the firmware's own simulator interface,
    stepped by the firmware's packets, until `running` is cleared (SIGTERM, Ctrl-C) or
    `end_time_s` of simulated time after the first packet."""

    running: bool

    def run(self) -> None: ...

    def close(self) -> None: ...

    def stats(self) -> dict[str, Any]: ...

    def summary(self) -> str:
        """The `sitl: stopped ...` line's text after "sitl: "."""
        ...


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog="sitl", description="tilt-rotor plant on a simulator link",
        epilog="protocols: dqflight (this project's FCU; every option applies), "
               "ardupilot-json (ArduPilot's JSON SITL interface: ArduPilot sends servo "
               "packets and drives simulated time) and px4-hil (PX4's simulator MAVLink API: "
               "HIL_SENSOR, HIL_GPS, HIL_STATE_QUATERNION out, HIL_ACTUATOR_CONTROLS in, "
               "lockstep on PX4's answers). With ardupilot-json and px4-hil the options "
               "--link, --truth-log, --end-time (after the first packet; default: serve until "
               "SIGTERM), --ideal-actuators, --sensors, --seed, --sysid, --stats and "
               "--position apply; --realtime, --control-rate, --hil-sensor-hz and "
               "--resend-ms are dqflight's only. ardupilot-json takes only the truth sensor "
               "profile (ArduPilot makes its sensors from the exact state), so --seed does "
               "nothing there.")
    p.add_argument("scenario", type=Path, help="scenario TOML (vehicle, start, disturbances)")
    p.add_argument("--protocol", choices=tuple(DEFAULT_LINKS), default=DQFLIGHT,
                   help="simulator protocol (default dqflight)")
    p.add_argument("--link", default=None,
                   help="simulator link URL (default per protocol: dqflight "
                        "udpin:127.0.0.1:4560, ardupilot-json udpin:127.0.0.1:9002, px4-hil "
                        "tcpin:127.0.0.1:4560)")
    p.add_argument("--realtime", action="store_true", help="pace by the wall clock")
    p.add_argument("--truth-log", type=Path,
                   help="write the ground-truth log (ULog) here, e.g. truth.ulg")
    p.add_argument("--end-time", type=float, metavar="S",
                   help="stop advancing this long after the flight starts (default: the "
                        "scenario's duration in lockstep, never in real time; with a firmware "
                        "protocol, after the first packet, default never)")
    p.add_argument("--control-rate", type=int, default=None,
                   help="control periods per second (default: the scenario's)")
    p.add_argument("--ideal-actuators", action="store_true")
    p.add_argument("--hil-sensor-hz", type=float, default=None,
                   help="with the truth profile: HIL_SENSOR rate in simulated time (0: off; "
                        "default 100)")
    p.add_argument("--sensors", metavar="PROFILE",
                   help="sensor profile: a name in config/sensors/ (truth, mocap-indoor, "
                        "degraded) or a .toml file (default: the scenario's, else truth)")
    p.add_argument("--seed", type=int, metavar="N",
                   help="seed of the sensors' noise (default: the scenario's seed)")
    p.add_argument("--resend-ms", type=float, default=None,
                   help="re-send an unanswered state after this wall time (default 5)")
    p.add_argument("--sysid", type=int, default=1)
    p.add_argument("--stats", type=Path,
                   help="write run statistics (JSON: counts, per-step stage times) here at exit")
    p.add_argument("--position", metavar="X,Y,Z",
                   help="start position in ENU metres (default: the scenario's)")
    return p


def _check_protocol_options(args: argparse.Namespace) -> None:
    """Refuse what the chosen protocol does not take (exit 2), fill in the defaults."""
    if args.protocol != DQFLIGHT:
        given = [name for name in DQFLIGHT_ONLY if getattr(args, name) not in (None, False)]
        if given:
            flag = "--" + given[0].replace("_", "-")
            raise ConfigError(f"{flag} does not apply to --protocol {args.protocol}: the "
                              "firmware sets the rates and drives simulated time")
    if args.link is None:
        args.link = DEFAULT_LINKS[args.protocol]
    if args.hil_sensor_hz is None:
        args.hil_sensor_hz = 100.0
    if args.resend_ms is None:
        args.resend_ms = 5.0


def main(argv: list[str] | None = None) -> int:
    stop_with_parent()
    args = build_parser().parse_args(argv)

    startup.guard()  # a stop while starting (loading the kernels, say) is looked at below
    try:
        _check_protocol_options(args)
        parse_url(args.link)  # before anything is opened
        check_output_path("--truth-log", args.truth_log)
        check_output_path("--stats", args.stats)
        scenario = load_scenario(args.scenario)
        if args.ideal_actuators:
            scenario = dataclasses.replace(scenario, ideal_actuators=True)
        if args.position is not None:
            try:
                xyz = tuple(float(v) for v in args.position.split(","))
            except ValueError:
                xyz = ()
            if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
                raise ConfigError(f"--position: expected X,Y,Z in metres, got {args.position}")
            scenario = dataclasses.replace(scenario, initial_position_enu_m=xyz)
        if args.sensors is not None:
            scenario = dataclasses.replace(scenario,
                                           sensors=resolve_sensor_profile(args.sensors))
        check_sensor_faults(scenario.sensor_faults, scenario.sensors, "--sensors")
        if args.seed is not None:
            if not 0 <= args.seed < 2**63:
                raise ConfigError(f"--seed: expected 0..2^63-1, got {args.seed}")
            scenario = dataclasses.replace(scenario, seed=args.seed)
        rate = args.control_rate or scenario.control_rate_hz
        if not 1 <= rate <= 1000:
            raise ConfigError(f"--control-rate: expected 1..1000 Hz, got {rate}")
        end = args.end_time
        if end is None and not args.realtime and args.protocol == DQFLIGHT:
            end = scenario.duration_s
        if end is not None and not (math.isfinite(end) and end > 0):
            raise ConfigError(f"--end-time: expected a positive number of seconds, got {end}")
        if args.protocol != DQFLIGHT:
            return _serve_firmware(args, scenario, end)
        server = SimulatorServer(scenario, args.link, truth_log=args.truth_log,
                                 end_time_s=end, realtime=args.realtime,
                                 control_rate_hz=rate, hil_sensor_hz=args.hil_sensor_hz,
                                 resend_ms=args.resend_ms, system_id=args.sysid,
                                 sensors=scenario.sensors, seed=scenario.seed)
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM before the loop ran: nothing flown
        print("sitl: stopped while starting", file=sys.stderr, flush=True)
        return 0
    except LinkError as exc:  # 2: bad URL, busy port, missing device; 1: peer not there
        print(f"sitl: {exc}", file=sys.stderr)
        return exc.exit_code
    except (ConfigError, ULogError) as exc:
        print(f"sitl: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a file that cannot be written: one line
        print(f"sitl: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2

    if startup.stop_requested():  # Ctrl-C or SIGTERM while it started: nothing flown
        server.close()
        print("sitl: stopped while starting", file=sys.stderr, flush=True)
        return 0

    def stop(_signum, _frame):
        server.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    print(f"sitl: serving {scenario.name} on {args.link} "
          f"({'real time' if args.realtime else 'lockstep'})", flush=True)
    server.run()
    if args.stats is not None:
        tmp = args.stats.with_suffix(".tmp")
        tmp.write_text(json.dumps(server.stats(), indent=2) + "\n")
        os.replace(tmp, args.stats)
    print(f"sitl: stopped at t = {server.state.time_us * 1e-6:.3f} s after {server.steps} "
          f"control periods; {server.resends} re-sends, {server.ignored_answers} answers "
          f"ignored, {server.rejected_bytes} bytes rejected, {server.skipped_s:.3f} s of wall "
          "time skipped", flush=True)
    return 0


def _serve_firmware(args: argparse.Namespace, scenario: Scenario, end_s: float | None) -> int:
    """Serve the plant to real firmware over its own simulator protocol until SIGTERM or
    Ctrl-C (or `end_s` of simulated time after the firmware's first packet)."""
    module = importlib.import_module(FIRMWARE_MODULES[args.protocol])
    try:
        server: FirmwareServer = module.Server(scenario, args.link, truth_log=args.truth_log,
                                               end_time_s=end_s, system_id=args.sysid)
    except LinkError as exc:
        print(f"sitl: {exc}", file=sys.stderr)
        return exc.exit_code
    except (ConfigError, ULogError) as exc:
        print(f"sitl: {exc}", file=sys.stderr)
        return 2

    if startup.stop_requested():  # Ctrl-C or SIGTERM while it started: nothing flown
        server.close()
        print("sitl: stopped while starting", file=sys.stderr, flush=True)
        return 0

    def stop(_signum: int, _frame: object) -> None:
        server.running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    print(f"sitl: serving {scenario.name} on {args.link} ({args.protocol}, lockstep driven "
          "by the firmware)", flush=True)
    server.run()
    if args.stats is not None:
        tmp = args.stats.with_suffix(".tmp")
        tmp.write_text(json.dumps(server.stats(), indent=2) + "\n")
        os.replace(tmp, args.stats)
    print(f"sitl: {server.summary()}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
